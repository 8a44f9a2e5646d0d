"""When the real-time planner starts a replanning step: on new input at once, the period as an upper bound.

The paper replans on a fixed period. A fixed period makes the robot's reaction time the period plus
the planning time: a prediction that lands just after a step started waits a whole period. In
``trigger = "event"`` mode (the default) the planner, whenever it is idle, starts a step as soon as

* a new occupancy prediction has arrived (one it has not planned against yet), or
* the robot has left the plan it is executing (farther than the planner's ``off_path_tol`` from
  tau_best: it was held, or the executor clamped it),

and in any case, so that a plan is published at least once every ``period_s``, once ``period_s`` less the
recent steps' planning time (``lead_s``, at most half the period) has passed since the last step started. The
period is the executor's heartbeat: its ``stale_limit_s`` (0.5 s by default, the period's default) holds the robot
when the newest plan is older. Started a whole period after the last start, a step's plan came ``period_s`` plus
the change in planning time after the last one, and the robot stopped for a state whenever that change was
positive (a real-time demo after the human's reach: 3 holds of 20 ms in 7 s, ``plan is 0.50 s old (limit
0.50 s)``). A step that is running is never interrupted (its result is published with the inputs it used);
the *anytime* option (``anytime_min_iterations``) lets it stop STOMP early, after at least that many iterations,
when a newer prediction is already waiting, so the next step starts from fresher input. ``trigger = "period"``
is the paper's fixed period.

Pure: no Zenoh, no clock of its own (times are passed in), unit-tested in
``tests/services/planner/test_replan.py``.
"""

from __future__ import annotations

from collections.abc import Hashable

__all__ = ["ReplanTrigger", "TRIGGERS"]

TRIGGERS = ("event", "period")
"""``event``: new input starts a step at once (period as the upper bound); ``period``: the fixed period."""


class ReplanTrigger:
    """Decides when the next replanning step starts.

    Args:
        period_s: Longest time between two published plans (s, > 0; :meth:`lead`); the only trigger in ``period``
            mode (between two step starts).
        mode: One of :data:`TRIGGERS`.

    Attributes:
        last_start: Time the last step started (None before the first).
        last_input: Identity of the occupancy the last step planned against (None: none yet).
        counts: Steps started per reason (``first``, ``occupancy``, ``departure``, ``period``).
    """

    def __init__(self, period_s: float, mode: str = "event") -> None:
        if not period_s > 0:
            raise ValueError(f"period_s must be > 0, got {period_s}")
        if mode not in TRIGGERS:
            raise ValueError(f"trigger must be one of {TRIGGERS}, got {mode!r}")
        self.period_s = float(period_s)
        self.mode = mode
        self.last_start: float | None = None
        self.last_input: Hashable | None = None
        self.counts: dict[str, int] = {"first": 0, "occupancy": 0, "departure": 0, "period": 0}

    def reason(self, now: float, occupancy: Hashable | None, departed: bool = False, lead_s: float = 0.0
               ) -> str | None:
        """Why a step should start at ``now``, or None to wait.

        Args:
            now: Current time (s, any monotonic clock).
            occupancy: Identity of the newest occupancy received (e.g. ``(demo_id, index, stamp)``; None:
                none yet).
            departed: Whether the robot has left the plan it executes.
            lead_s: The recent steps' planning time (s): the period's step starts that much early (:meth:`lead`).

        Returns:
            ``"first"``, ``"occupancy"``, ``"departure"``, ``"period"`` or None.
        """
        if self.last_start is None:
            return "first"
        if self.mode == "event":
            if occupancy is not None and occupancy != self.last_input:
                return "occupancy"
            if departed:
                return "departure"
        if now - self.last_start >= self.period_s - self.lead(lead_s) - 1e-9:
            return "period"
        return None

    def lead(self, lead_s: float) -> float:
        """How much earlier than a period after the last start the period's step starts (event mode; s).

        ``lead_s`` (the recent planning time) clipped to ``[0, period_s / 2]``: the plan lands within the period
        of the last one. The steps' starts, not their ends, are a period less the lead apart: the plans come a
        little more often than the period (0.42-0.46 s apart at 0.5 s in the demo), which leaves the margin of a
        planning time that varies (timed from the last plan's publication, the plans came the period apart and
        the robot held once per run when a step planned longer than the last five). A planner slower than half its
        period replans back to back, its plans its planning time apart. 0 in ``period`` mode, the paper's fixed
        period.
        """
        if self.mode != "event" or not lead_s > 0:
            return 0.0
        return min(float(lead_s), 0.5 * self.period_s)

    def start(self, now: float, occupancy: Hashable | None, reason: str) -> None:
        """Record that a step starts at ``now`` planning against ``occupancy``, for ``reason``."""
        self.last_start = float(now)
        self.last_input = occupancy
        self.counts[reason] = self.counts.get(reason, 0) + 1

    def wait_s(self, now: float, lead_s: float = 0.0) -> float:
        """Seconds until the period forces the next step (0 when due, and before the first step)."""
        if self.last_start is None:
            return 0.0
        return max(0.0, self.last_start + self.period_s - self.lead(lead_s) - now)

    def newer_than_planned(self, occupancy: Hashable | None) -> bool:
        """Whether ``occupancy`` is not the one the running step plans against (the anytime test)."""
        return occupancy is not None and occupancy != self.last_input
