"""A keypoint recording on the sensor's timeline: holds, dropped frames, the gap between demonstrations, loop."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from services.tracker.config import PlaybackConfig
from services.tracker.playback import Playback
from shared.keypoints.library import KeypointDemo


def _demo(demo: int, frames: list[int], names=("pelvis", "r_wrist")) -> KeypointDemo:
    pos = np.stack([np.full((len(names), 3), float(f)) for f in frames])
    return KeypointDemo(demo, np.array(frames), list(names), pos)


def test_each_demonstration_is_held_before_and_after_with_a_gap_between() -> None:
    cfg = PlaybackConfig(rate_hz=10.0, lead_s=0.3, hold_s=0.2, gap_s=0.5)
    play = Playback([_demo(0, [0, 1, 3]), _demo(1, [5, 6])], cfg)  # frame 2 of the first was dropped
    frames = list(play.frames())
    got = [(f.frame, f.demo, float(f.positions[0, 0])) for f in frames]
    assert got == [(0, 0, 0.0), (1, 0, 0.0), (2, 0, 0.0),             # lead: the first frame held 0.3 s
                   (3, 0, 0.0), (4, 0, 1.0), (6, 0, 3.0),             # the demonstration, its dropped frame too
                   (7, 0, 3.0), (8, 0, 3.0),                          # hold: the last frame 0.2 s
                   (14, 1, 5.0), (15, 1, 5.0), (16, 1, 5.0),          # 0.5 s gap, then the next one's lead
                   (17, 1, 5.0), (18, 1, 6.0), (19, 1, 6.0), (20, 1, 6.0)]
    np.testing.assert_allclose([f.t for f in frames], [f.frame / 10.0 for f in frames])
    assert play.duration_s() == pytest.approx(2.6)
    assert play.names == ["pelvis", "r_wrist"]


def test_a_held_frame_is_one_with_every_point_seen() -> None:
    d = _demo(0, [0, 1, 2])
    d.positions[0, 1] = np.nan  # the first frame lost the wrist
    play = Playback([d], PlaybackConfig(rate_hz=10.0, lead_s=0.1, hold_s=0.0, gap_s=0.0))
    first = next(iter(play.frames()))
    assert np.all(np.isfinite(first.positions)) and first.positions[0, 0] == 1.0


def test_loop_and_refusals() -> None:
    play = Playback([_demo(0, [0, 1])], PlaybackConfig(rate_hz=10.0, lead_s=0.0, hold_s=0.0, gap_s=0.0, loop=True))
    assert [f.frame for f in itertools.islice(play.frames(), 5)] == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="no demonstration"):
        Playback([], PlaybackConfig())
    with pytest.raises(ValueError, match="different points"):
        Playback([_demo(0, [0]), _demo(1, [0], names=("pelvis",))], PlaybackConfig())
