"""The executed reference: a plan's chosen waypoints by time and by (weighted) configuration-space length."""

from __future__ import annotations

import numpy as np
import pytest

from services.executor.reference import Reference


def test_length_along_a_bent_path_checked_by_hand() -> None:
    ref = Reference(np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.4]]), dt=0.5)
    assert ref.length == pytest.approx(0.7) and ref.duration == pytest.approx(1.0)
    np.testing.assert_allclose(ref.at_length(0.15), [0.15, 0.0])
    np.testing.assert_allclose(ref.at_length(0.5), [0.3, 0.2])
    np.testing.assert_allclose(ref.at_length(-1.0), [0.0, 0.0])  # held at the ends
    np.testing.assert_allclose(ref.at_length(9.0), [0.3, 0.4])
    np.testing.assert_allclose(ref.at(0.25), [0.15, 0.0])  # the same path by time: 0.5 s per segment


def test_weights_scale_each_joints_share_of_the_length() -> None:
    ref = Reference(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), dt=1.0, weights=np.array([0.5, 2.0]))
    assert ref.length == pytest.approx(0.5 + 2.0)
    np.testing.assert_allclose(ref.at_length(1.5), [1.0, 0.5])  # 0.5 along joint 0, then 1.0 of joint 1's 2.0


def test_a_time_just_below_the_end_reads_the_last_segment() -> None:
    """tau / dt can round up to the last index although tau < duration: that read one waypoint past the end."""
    ref = Reference(np.linspace([0.0], [1.0], 11), dt=0.312005658747612)
    tau = np.nextafter(ref.duration, 0.0)
    assert tau < ref.duration
    np.testing.assert_allclose(ref.at(tau), [1.0], atol=1e-12)


def test_the_nearest_point_by_time_and_by_length_checked_by_hand() -> None:
    ref = Reference(np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.4]]), dt=0.5)
    assert ref.nearest(np.array([0.1, 0.05]), within=9.0) == pytest.approx(0.5 / 3)  # a third of segment 0
    assert ref.nearest(np.array([0.4, 0.2]), within=9.0) == pytest.approx(0.75)  # half way along segment 1
    assert ref.nearest(np.array([0.4, 0.2]), within=9.0, by_length=True) == pytest.approx(0.5)
    assert ref.nearest(np.array([-1.0, 0.0]), within=9.0) == 0.0  # behind the start: the start
    assert ref.nearest(np.array([0.4, 0.2]), within=0.5) == pytest.approx(0.5)  # segment 1 is beyond the window


def test_the_nearest_point_neither_skips_a_wait_nor_joins_a_later_pass() -> None:
    """A plan that waits at its start is joined at its start; a path back near the arm later is not joined there."""
    waits = Reference(np.array([[0.0], [0.0], [0.0], [1.0]]), dt=0.1)
    assert waits.nearest(np.array([1e-8]), within=9.0) == 0.0
    there_and_back = Reference(np.array([[0.0, 0.0], [1.0, 0.0], [0.2, 0.04]]), dt=1.0)
    q = np.array([0.2, 0.04])  # 0.04 from the way out, on the way back
    assert there_and_back.nearest(q, within=0.5) == pytest.approx(0.2)  # the way back begins 1 s in
    assert there_and_back.nearest(q, within=9.0) == pytest.approx(2.0)


def test_the_nearest_point_weighs_the_joints_as_the_length_does() -> None:
    ref = Reference(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), dt=1.0, weights=np.array([1.0, 10.0]))
    q = np.array([0.5, 0.45])  # 0.45 from segment 0 (along j0), 0.5 from segment 1 (along j1)
    assert ref.nearest(q, within=9.0) == pytest.approx(1.45)  # j1's 0.45 weighs 4.5: segment 1 is nearer
    assert Reference(ref.waypoints, dt=1.0).nearest(q, within=9.0) == pytest.approx(0.5)  # unweighted: segment 0
