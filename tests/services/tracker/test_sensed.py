"""A demonstration through the tracker in memory: what playing it as a keypoint recording gives, seeded noise."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from services.tracker.config import PlaybackConfig
from services.tracker.core import TrackerConfig, TrackerCore
from services.tracker.demos import reach_poses
from services.tracker.playback import Playback
from services.tracker.reach import recorded_start
from services.tracker.sensed import sense_reach
from shared.keypoints.library import read_keypoint_csv, write_keypoint_library
from shared.library import MotionLibrary
from shared.synthetic import generate_library


@pytest.fixture(scope="module")
def library() -> MotionLibrary:
    return generate_library(n_classes=2, n_demos=2, seed=4)


def test_the_poses_are_those_of_a_keypoint_recording_played_into_the_tracker(library: MotionLibrary,
                                                                            tmp_path: Path) -> None:
    """By hand: the library written as keypoint CSVs, played as ``foresight tracker --from`` plays them."""
    demo = library.demos[0]
    one = dataclasses.replace(library, demos=[demo])
    write_keypoint_library(one, tmp_path)
    kd = read_keypoint_csv(tmp_path / f"{demo.class_name}.csv")
    play = Playback(kd, PlaybackConfig(gap_s=0.0))
    core, messages = TrackerCore(TrackerConfig()), []
    for fr in play.frames():
        messages += core.on_frame(fr.t, play.names, fr.positions, fr.frame).messages
    by_hand = reach_poses(messages, set())
    first = [p for p in by_hand if p.demo_id == by_hand[0].demo_id]

    sensed = sense_reach(demo.features, library.feature_names)
    assert sensed is not None and len(sensed.features) == len(first) > 20
    assert sensed.end - sensed.start + 1 == len(first)  # one pose per sample, none bridged
    assert np.allclose(sensed.features, [p.features for p in first], atol=1e-3)  # the CSV's 5 decimals
    # noise-free, the reach starts where the trainer's --time-from tracker cuts the demonstration
    assert sensed.start == recorded_start(demo.features, TrackerConfig()) > 0


def test_the_same_seed_gives_the_same_poses_another_seed_others(library: MotionLibrary) -> None:
    demo = library.demos[2]
    a, b, c = (sense_reach(demo.features, library.feature_names, 0.02, seed) for seed in (5, 5, 6))
    assert a is not None and b is not None and c is not None
    assert np.array_equal(a.features, b.features) and (a.start, a.end) == (b.start, b.end)
    assert len(a.features) != len(c.features) or not np.allclose(a.features, c.features)
    clean = sense_reach(demo.features, library.feature_names)
    assert clean is not None and abs(a.start - clean.start) <= 3  # noise moves the start a little, not the reach


def test_a_hand_that_never_leaves_rest_is_no_reach(library: MotionLibrary) -> None:
    still = np.repeat(library.demos[0].features[:1], 60, axis=0)
    assert sense_reach(still, library.feature_names, 0.005) is None


def test_bad_inputs_are_refused(library: MotionLibrary) -> None:
    f = library.demos[0].features
    with pytest.raises(ValueError, match="noise_m: must be a finite number >= 0, got -0.01"):
        sense_reach(f, library.feature_names, -0.01)
    with pytest.raises(ValueError, match="herakles"):
        sense_reach(f[:, :3], ["a", "b", "c"])
    with pytest.raises(ValueError, match="not coco17"):
        sense_reach(f, library.feature_names, config=TrackerConfig(layout="coco17"))
