"""The One-Euro filter over a whole recorded sequence (services/tracker/filters.py)."""

from __future__ import annotations

import numpy as np
import pytest

from services.tracker.filters import OneEuroFilter, smooth_sequence


def test_smooth_sequence_is_the_filter_frame_by_frame() -> None:
    """The whole sequence at once equals a fresh filter fed one frame every ``1 / rate_hz`` s, value for value."""
    rng = np.random.default_rng(3)
    values = np.cumsum(rng.normal(0.0, 0.05, (40, 12)), axis=0)
    f = OneEuroFilter(0.7, 0.3)
    looped = np.array([f(x, k / 30.0) for k, x in enumerate(values)])
    batched = smooth_sequence(values, 30.0, 0.7, 0.3)
    assert batched.shape == (40, 12) and batched.dtype == np.float64
    np.testing.assert_array_equal(batched, looped)
    np.testing.assert_array_equal(batched[0], values[0])
    assert not np.allclose(batched[1:], values[1:])  # it smooths


def test_smooth_sequence_keeps_its_shape_when_empty_and_refuses_a_bad_rate() -> None:
    """No samples: ``(0, N)``; a rate that is not > 0 is a ValueError naming it."""
    assert smooth_sequence(np.zeros((0, 12)), 30.0).shape == (0, 12)
    with pytest.raises(ValueError, match="rate_hz"):
        smooth_sequence(np.zeros((3, 12)), 0.0)
