"""PoseClock: a pose per frame near the library's rate, poses on the library's clock otherwise."""

from __future__ import annotations

import numpy as np
import pytest

from services.tracker.resample import PoseClock


def _feed(clock: PoseClock, stamps: np.ndarray) -> list[tuple[float, np.ndarray]]:
    """Frames whose features are their stamp (a ramp): every interpolated pose must equal its own time."""
    out, last = [], None
    for t in stamps:
        f = np.full(12, t)
        out += clock.poses(last, float(t), f)
        last = (float(t), f)
    return out


def test_poses_are_on_the_rate_grid_from_the_first_frame_and_interpolated() -> None:
    clock = PoseClock(30.0)
    assert clock.follow(120.0)  # resampling starts
    stamps = 5.0 + np.arange(0, 241) / 120.0  # 2 s of a 120 Hz sensor
    poses = _feed(clock, stamps)
    t = np.array([p[0] for p in poses])
    assert t[0] == 5.0 and np.allclose(np.diff(t), 1 / 30.0) and t[-1] <= stamps[-1] + 1e-9
    assert len(poses) == 61 and clock.made == 61
    assert all(np.allclose(f, s) for s, f in poses)  # linear in time: exact


def test_a_slow_sensor_gets_poses_between_its_frames_and_none_past_the_newest() -> None:
    clock = PoseClock(30.0)
    clock.follow(12.0)
    stamps = np.arange(0, 13) / 12.0  # 1 s at 12 Hz
    out, last = [], None
    for s in stamps:
        got = clock.poses(last, float(s), np.full(12, s))
        assert all(t <= s + 1e-9 for t, _ in got)  # never later than the newest frame
        out += got
        last = (float(s), np.full(12, s))
    assert len(out) == 31 and all(np.allclose(f, t) for t, f in out)


def test_the_mode_follows_the_sensor_with_hysteresis() -> None:
    clock = PoseClock(30.0)
    assert not clock.follow(None) and not clock.resampling  # the rate not known yet
    assert not clock.follow(32.0) and not clock.resampling  # 7 % off: a pose per frame
    assert clock.follow(34.0) and clock.resampling  # 13 % off
    assert not clock.follow(32.0) and clock.resampling  # 7 %: still (leaves under 5 %)
    assert not clock.follow(31.0) and not clock.resampling  # 3 %
    clock.follow(60.0)
    clock.reset()
    assert not clock.resampling


def test_bad_options_are_refused() -> None:
    with pytest.raises(ValueError, match="rate_hz"):
        PoseClock(0.0)
    with pytest.raises(ValueError, match="leave"):
        PoseClock(30.0, enter=0.05, leave=0.1)
