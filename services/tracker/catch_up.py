"""Which frames of a backlog the tracker fits: all of them, until they stand for too long to catch up.

The tracker's worker takes every frame waiting at once (:class:`shared.backlog.Backlog`). Fitting them all, in
order, kept every frame's pose, but with a sensor faster than the fit (5-13 ms a frame; a 120 Hz sensor sends one
every 8.3 ms) the waiting frames grew without bound: the poses came 0.5 s after the person at 60 Hz and 4.5 s at
240 Hz on a loaded 2-core machine, and the predictor and planner avoided where the person had been. A batch that
stands for at most :data:`CATCH_UP_S` of the sensor's time is fitted whole (a burst flushed after a network stall
is still every frame); a longer one is thinned to every k-th frame, k intervals at most ``spacing_s``, and its
newest, so the next batch is shorter and the tracker catches up within a few batches. The time a batch stands for
and k come from the median interval between its frames, not from their first and last stamps: one frame stamped
seconds ahead (a sensor's glitch, which the core refuses by itself) made a short batch look long, and the frames
measured against it were dropped (a review: a reach cut from 62 poses to 16). ``spacing_s`` is a third of the
tracker's ``max_gap_s`` (the caller's), so two kept frames are never a gap that ends the reach under way, even
when one kept frame between them is refused.

Pure: unit-tested in ``tests/services/tracker/test_catch_up.py``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["CATCH_UP_S", "frames_to_fit"]

CATCH_UP_S = 0.1
"""The longest time (s) a batch of waiting frames may stand for and be fitted whole: three frames of a 30 Hz sensor."""


def frames_to_fit(stamps: Sequence[float], spacing_s: float, span_s: float = CATCH_UP_S) -> list[int]:
    """The indices of a batch's frames to fit, in order.

    Args:
        stamps: The waiting frames' stamps (s), oldest first (as received: not necessarily increasing).
        spacing_s: Once thinned, the most time between two frames kept.
        span_s: A batch whose frames stand for at most this (its median interval times its intervals) is kept whole.

    Returns:
        Every index when the batch stands for at most ``span_s`` (or its interval is unknown); else every k-th
        from the first, with k the most whole median intervals within ``spacing_s`` (at least 1), and the newest.
    """
    n = len(stamps)
    if n < 3:
        return list(range(n))
    dt = float(np.median(np.diff(np.asarray(stamps, dtype=np.float64))))
    if not dt > 0 or dt * (n - 1) <= span_s:
        return list(range(n))
    k = max(1, int(spacing_s / dt + 1e-9))
    return [*range(0, n - 1, k), n - 1]
