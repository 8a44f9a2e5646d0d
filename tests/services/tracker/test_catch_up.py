"""Which frames of a backlog the tracker fits: all, until they stand for too long to catch up."""

from __future__ import annotations

import numpy as np

from services.tracker.catch_up import CATCH_UP_S, frames_to_fit


def test_a_short_batch_is_fitted_whole() -> None:
    """A burst flushed after a stall (here 3 frames of a 30 Hz sensor) keeps every frame."""
    assert frames_to_fit([], 0.1) == []
    assert frames_to_fit([5.0], 0.1) == [0]
    stamps = [5.0, 5.0 + 1 / 30, 5.0 + 2 / 30, 5.0 + 3 / 30]
    assert frames_to_fit(stamps, 0.1) == [0, 1, 2, 3]
    assert max(stamps) - min(stamps) <= CATCH_UP_S + 1e-9


def test_a_long_batch_is_thinned_to_frames_spacing_apart_with_its_first_and_newest() -> None:
    stamps = list(10.0 + np.arange(240) / 240)  # a second of a 240 Hz sensor waiting
    keep = frames_to_fit(stamps, 0.1)
    kept = np.array([stamps[i] for i in keep])
    assert keep[0] == 0 and keep[-1] == 239 and keep == sorted(keep)
    gaps = np.diff(kept)
    assert np.all(gaps <= 0.1 + 1e-9) and np.all(gaps[:-1] >= 0.1 - 1 / 240)  # never a gap that ends a reach
    assert len(keep) <= 1 + 1.0 / 0.1 + 1


def test_a_frame_stamped_seconds_ahead_does_not_thin_the_frames_around_it_away() -> None:
    """The span was the first and last stamps': one frame stamped 5 s ahead made 13 frames of a 30 Hz sensor a long
    batch whose frames after the glitch were all dropped (a review: the reach cut from 62 poses to 16)."""
    stamps = [i / 30 for i in range(13)]
    stamps[1] += 5.0
    keep = frames_to_fit(stamps, 0.1)
    regular = [stamps[i] for i in keep if i != 1]
    assert keep[-1] == 12 and np.max(np.diff(regular)) <= 0.1 + 1e-9, keep
    assert frames_to_fit(stamps[:3], 0.1) == [0, 1, 2]  # a short batch with the glitch: whole, the core refuses it
