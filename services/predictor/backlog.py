"""What the predictor does when poses arrive faster than it predicts: a bounded, ordered backlog.

Zenoh hands each sample to a callback; a predictor that spends longer on a pose than the stream
leaves between two poses would queue them without bound (measured before this module: at 300 Hz
the pose -> occupancy latency grew from 37 s to 55 s within a minute). So the callback only appends
to a :class:`Backlog` and one worker drains it in batches:

* every pose is *observed* (the class likelihoods accumulate every sample: no evidence is lost);
* the occupancy grid, the expensive part, is built only for the poses :func:`occupancy_due` marks:
  in real time the newest pose of a run of consecutive poses of one demonstration, in lock-step
  every pose (the planner and the experiments count on each tick's grids);
* in real time a :class:`GridPacer` also spaces the grids at least ``grid_interval_s`` apart: a grid
  per pose at 300 Hz is 300 grids a second for the planner, the executor and its log to decode,
  validate and store, though the next plan can use only the newest; the newest pose still gets its
  grid within one interval;
* the backlog (:class:`shared.backlog.Backlog`) holds at most ``limit`` messages; beyond it the oldest are
  dropped and counted.

Pure (no Zenoh): unit-tested in ``tests/services/predictor/test_backlog.py``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Generic, TypeVar

from shared.backlog import Backlog
from shared.protocol import HumanPose

__all__ = ["Backlog", "GridPacer", "occupancy_due"]  # Backlog: shared.backlog, re-exported

T = TypeVar("T")


def occupancy_due(batch: Sequence[object]) -> list[bool]:
    """Which messages of a batch get an occupancy grid (True only for poses).

    A lock-step pose (``tick >= 0``) always does. A real-time pose does when it is the last of a run of
    consecutive real-time poses of the same demonstration: the next message is not one (a marker,
    another demonstration, a lock-step pose) or there is none.

    Args:
        batch: Messages in arrival order.

    Returns:
        One flag per message.
    """
    out = []
    for i, msg in enumerate(batch):
        if not isinstance(msg, HumanPose):
            out.append(False)
        elif msg.tick >= 0:
            out.append(True)
        else:
            nxt = batch[i + 1] if i + 1 < len(batch) else None
            out.append(not (isinstance(nxt, HumanPose) and nxt.tick < 0 and nxt.demo_id == msg.demo_id))
    return out


class GridPacer(Generic[T]):
    """Spaces real-time grids at least ``interval_s`` apart; a skipped newest pose is owed its grid.

    Args:
        interval_s: Shortest time between two grids (0: no spacing).
    """

    def __init__(self, interval_s: float) -> None:
        if not interval_s >= 0:
            raise ValueError(f"grid interval must be >= 0 s, got {interval_s}")
        self.interval_s = float(interval_s)
        self.last = -float("inf")
        self.owed: T | None = None  # the newest pose, skipped: it gets its grid once due

    def due(self, now: float) -> bool:
        """Whether a grid may be published at ``now`` (monotonic s)."""
        return now - self.last >= self.interval_s

    def skipped(self, pose: T) -> None:
        """The newest pose ``pose`` got no grid: it is owed one."""
        self.owed = pose

    def sent(self, now: float) -> None:
        """A grid was published at ``now``: nothing is owed."""
        self.last = now
        self.owed = None

    def forget(self) -> None:
        """Nothing is owed any more (a newer pose came, or a new demonstration started)."""
        self.owed = None

    def wait_s(self, now: float) -> float | None:
        """Seconds until the owed grid is due (None: nothing owed)."""
        return max(0.0, self.last + self.interval_s - now) if self.owed is not None else None
