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
