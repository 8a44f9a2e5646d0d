"""Which frames of a backlog the tracker fits: all, until they span too long to catch up."""

from __future__ import annotations

import numpy as np

from services.tracker.catch_up import CATCH_UP_S, frames_to_fit


def test_a_short_batch_is_fitted_whole() -> None:
    """A burst flushed after a stall (here 3 frames of a 30 Hz sensor) keeps every frame."""
    assert frames_to_fit([], 0.15) == []
    assert frames_to_fit([5.0], 0.15) == [0]
    stamps = [5.0, 5.0 + 1 / 30, 5.0 + 2 / 30]
    assert frames_to_fit(stamps, 0.15) == [0, 1, 2]
    assert max(stamps) - min(stamps) <= CATCH_UP_S


def test_a_long_batch_is_thinned_to_frames_spacing_apart_with_its_first_and_newest() -> None:
    stamps = list(10.0 + np.arange(240) / 240)  # a second of a 240 Hz sensor waiting
    keep = frames_to_fit(stamps, 0.15)
    kept = np.array([stamps[i] for i in keep])
    assert keep[0] == 0 and keep[-1] == 239 and keep == sorted(keep)
    gaps = np.diff(kept)
    assert np.all(gaps[:-1] >= 0.15) and np.all(gaps <= 0.15 + 1 / 240 + 1e-9)  # never a gap that ends a reach
    assert len(keep) <= 1 + 1.0 / 0.15 + 1


def test_a_frame_stamped_before_the_last_kept_is_left_to_the_core() -> None:
    """Out-of-order stamps are not kept by the thinning (the core would refuse them as 'order')."""
    stamps = [0.0, 0.2, 0.1, 0.4, 0.45]
    assert frames_to_fit(stamps, 0.15) == [0, 1, 3, 4]
