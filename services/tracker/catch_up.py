"""Which frames of a backlog the tracker fits: all of them, until they span too long to catch up.

The tracker's worker takes every frame waiting at once (:class:`shared.backlog.Backlog`). Fitting them all, in
order, kept every frame's pose, but with a sensor faster than the fit (5-13 ms a frame; a 120 Hz sensor sends one
every 8.3 ms) the waiting frames grew without bound: the poses came 0.5 s after the person at 60 Hz and 4.5 s at
240 Hz on a loaded 2-core machine, and the predictor and planner avoided where the person had been. A batch whose
stamps span at most :data:`CATCH_UP_S` is fitted whole (a burst flushed after a network stall is still every
frame); a longer one is thinned to frames at least ``spacing_s`` apart, always with its newest, so the next batch
is shorter and the tracker catches up within a few batches. ``spacing_s`` is kept under the tracker's
``max_gap_s`` (the caller passes half of it), so thinning never makes a gap that ends the reach under way; the
frames between are bridged like any dropped frames.

Pure: unit-tested in ``tests/services/tracker/test_catch_up.py``.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["CATCH_UP_S", "frames_to_fit"]

CATCH_UP_S = 0.1
"""The longest span of stamps (s) a batch of waiting frames is fitted whole over: three frames of a 30 Hz sensor."""


def frames_to_fit(stamps: Sequence[float], spacing_s: float, span_s: float = CATCH_UP_S) -> list[int]:
    """The indices of a batch's frames to fit, in order.

    Args:
        stamps: The waiting frames' stamps (s), oldest first (as received: not necessarily increasing).
        spacing_s: Once thinned, the least time between two frames kept (the newest is always kept).
        span_s: A batch whose stamps span at most this is kept whole.

    Returns:
        Every index when the batch spans at most ``span_s``; else the first frame, each later one at least
        ``spacing_s`` after the last kept, and the newest.
    """
    n = len(stamps)
    if n == 0 or max(stamps) - min(stamps) <= span_s:
        return list(range(n))
    keep = [0]
    for i in range(1, n - 1):
        if stamps[i] - stamps[keep[-1]] >= spacing_s:
            keep.append(i)
    return keep + [n - 1]
