"""Lock-step rules: the simulated clock, which plan runs when, when the robot holds, and the tick inboxes.

No Zenoh here: each service's loop subscribes, feeds these objects and publishes what they return
(docs/protocol.md; Fig. 4 of Mainprice & Berenson 2013).

Replanning step n = 0, 1, ... covers the simulated time ``[t_n, t_n + P)``, ``t_n = n * P``:

* the executor (the simulation master, :class:`LockstepMaster`) adopts the newest plan of tick
  <= n-1 (plan n-1 is executed during step n), decides once whether the robot holds during the step
  (plan or occupancy older than the stale limit, ages measured in simulated time from the message's
  tick: a message of tick k counts as received at ``k * P``), simulates ``substeps`` states stamped
  ``t_n + h .. t_n + P`` and sends ClockTick n; then it waits for the plan of tick n
  (:meth:`PlanInbox.wait_plan`);
* the replayer publishes its poses of tick n on ClockTick n, each tick of the run once and in turn, and the planner
  plans tick n from the last robot state of tick n (where plan n starts) and the prediction of tick n-1:
  the clock's followers, :mod:`shared.lockstep_followers`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from shared.protocol import ClockTick, Plan, RobotState

__all__ = ["StepClock", "Received", "PlanInbox", "Adoption", "SimulatedArm", "StepOutcome", "LockstepMaster",
           "FIRST_PLAN"]

FIRST_PLAN = "waiting for the first plan"
"""The hold reason before any plan was adopted (:meth:`services.executor.core.ExecutorCore.stale_reason`)."""


@dataclass(frozen=True)
class StepClock:
    """Simulated time of the lock-step run.

    Attributes:
        period: P, simulated seconds per replanning step (clock tick).
        substeps: Simulation steps (one RobotState each) per replanning step.
    """

    period: float
    substeps: int

    @property
    def h(self) -> float:
        """Seconds per simulation substep, ``P / substeps``."""
        return self.period / self.substeps

    def start(self, n: int) -> float:
        """``t_n = n * P``, the start of step n (the stamp of ClockTick n)."""
        return n * self.period

    def substep_end(self, n: int, i: int) -> float:
        """End of substep i of step n, ``t_n + (i + 1) h`` (no drift from summing h)."""
        return self.start(n) + (i + 1) * self.h

    def received_at(self, tick: int) -> float:
        """The simulated time a message of ``tick`` counts as received: ``tick * P``."""
        return tick * self.period


@dataclass(frozen=True)
class Received:
    """What the executor has received so far (its :class:`PlanInbox` now).

    Attributes:
        plan: The newest valid plan, or None.
        seq: How many valid plans arrived (tells a new plan from one already adopted).
        occupancy_tick: Tick of the newest occupancy grid (-1: none, or real-time grids).
        occupancy_time: Arrival (monotonic wall clock) of the newest occupancy grid, or None.
    """

    plan: Plan | None = None
    seq: int = 0
    occupancy_tick: int = -1
    occupancy_time: float | None = None


class PlanInbox:
    """The executor's inbox: the newest valid plan and occupancy, filled from the transport's threads."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._now = Received()
        self._end_tick: int | None = None  # tick of the observed demonstration's last pose, once it ended

    def put_plan(self, plan: Plan) -> None:
        """A valid plan arrived (its joints already checked)."""
        with self._cond:
            self._now = Received(plan, self._now.seq + 1, self._now.occupancy_tick, self._now.occupancy_time)
            self._cond.notify_all()

    def put_occupancy(self, tick: int, arrival: float) -> None:
        """An occupancy grid of ``tick`` arrived at ``arrival`` (monotonic s); the newest tick is kept."""
        with self._cond:
            now = self._now
            self._now = Received(now.plan, now.seq, max(now.occupancy_tick, tick), arrival)
            self._cond.notify_all()

    def put_marker(self, event: str, tick: int) -> None:
        """A demonstration marker arrived: an end carries the tick of the demonstration's last pose."""
        with self._cond:
            self._end_tick = tick if event == "end" else None
            self._cond.notify_all()

    def latest(self) -> Received:
        """What has arrived so far."""
        with self._cond:
            return self._now

    def wait_plan(self, tick: int, timeout: float, stop: threading.Event,
                  idle: Callable[[], None] | None = None) -> bool:
        """Whether a plan of ``tick`` or later arrived within ``timeout`` wall s (``stop`` ends the wait).

        ``idle`` is called about every 0.1 s while waiting (e.g. to flush a log), never under the inbox's lock: the
        transport's thread delivering the plan does not wait for it.
        """
        return self._wait(lambda: self._now.plan is not None and self._now.plan.tick >= tick, timeout, stop, idle)

    def wait_occupancy(self, tick: int, timeout: float, stop: threading.Event,
                       idle: Callable[[], None] | None = None) -> bool:
        """Whether the grid of ``tick`` (or later) arrived, or none will: the demonstration ended before ``tick``.

        The prediction of tick n is made while plan n is, from the same tick's poses: which of the two reaches the
        executor first is up to the machine. Step n+1 judges the grid's age, so it waits for both, and a run
        holds or moves the same way on every machine.
        """
        def done() -> bool:
            return self._now.occupancy_tick >= tick or (self._end_tick is not None and self._end_tick < tick)

        return self._wait(done, timeout, stop, idle)

    def _wait(self, done: Callable[[], bool], timeout: float, stop: threading.Event,
              idle: Callable[[], None] | None) -> bool:
        deadline = time.monotonic() + timeout
        while not stop.is_set():
            with self._cond:
                if done():
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                if self._cond.wait_for(done, min(left, 0.1)):
                    return True
            if idle is not None:
                idle()
        return False


class Adoption:
    """Which received plan the robot executes next; each plan is adopted at most once."""

    def __init__(self) -> None:
        self.seq = 0

    def lockstep(self, received: Received, n: int) -> Plan | None:
        """At the start of step n: the newest plan if it is new and of tick <= n-1 (plan n-1 runs during step n)."""
        if received.plan is not None and received.seq != self.seq and received.plan.tick <= n - 1:
            self.seq = received.seq
            return received.plan
        return None

    def realtime(self, received: Received) -> Plan | None:
        """In real time: the newest plan if it is new (it starts now)."""
        if received.plan is not None and received.seq != self.seq:
            self.seq = received.seq
            return received.plan
        return None


class SimulatedArm(Protocol):
    """What :class:`LockstepMaster` drives (:class:`services.executor.core.ExecutorCore` is one).

    Attributes:
        t: Simulated time, seconds.
        q: ``(D,)`` current configuration.
        goal: Index of the goal being executed (-1 before the first plan).
        reached: Whether that goal is reached.
    """

    t: float
    q: np.ndarray
    goal: int
    reached: bool

    def adopt(self, plan: Plan, stamp: float | None = None) -> None:
        """Start executing ``plan``; it counts as received at ``stamp``."""

    def note_occupancy(self, stamp: float | None = None) -> None:
        """An occupancy prediction counts as received at ``stamp``."""

    def stale_reason(self, t: float | None = None) -> str:
        """Why the robot must hold at ``t`` ("" when it may move)."""

    def step(self, h: float, hold_reason: str | None = None) -> None:
        """Advance ``h`` seconds, holding when ``hold_reason`` is non-empty."""

    @property
    def remaining(self) -> float:
        """What is left of the plan being executed (0: at its end, or no plan)."""

    def state(self, tick: int, stamp: float | None = None) -> RobotState:
        """The current state as a message."""


@dataclass
class StepOutcome:
    """One simulated replanning step.

    Attributes:
        tick: n.
        reason: Why the robot held during the whole step ("": it moved).
        states: The ``substeps`` RobotState messages of tick n, stamped ``t_n + h .. t_n + P``.
        clock: ClockTick n, sent once the states are out.
        goal: Goal executed at the end of the step.
        reached: Whether it is reached.
    """

    tick: int
    reason: str
    states: list[RobotState] = field(default_factory=list)
    clock: ClockTick | None = None
    goal: int = -1
    reached: bool = False

    @property
    def held(self) -> bool:
        """Whether the robot held during the step."""
        return bool(self.reason)

    @property
    def hold_news(self) -> bool:
        """A hold worth reporting: any but the wait for the first plan at step 0."""
        return self.held and (self.reason != FIRST_PLAN or self.tick > 0)


class LockstepMaster:
    """The executor's lock-step rules: plan adoption, the hold decided once per step, the substeps and the tick.

    Args:
        arm: The simulated arm.
        clock: Period and substeps.
    """

    def __init__(self, arm: SimulatedArm, clock: StepClock) -> None:
        self.arm = arm
        self.clock = clock
        self.adoption = Adoption()

    def initial_state(self) -> RobotState:
        """The state published before step 0 (tick -1, stamp 0)."""
        return self.arm.state(-1, 0.0)

    def step(self, n: int, received: Received) -> StepOutcome:
        """Simulate step n with what has been received by its start.

        Args:
            n: The step (tick) index.
            received: The executor's inbox at the start of the step.

        Returns:
            The step's states, hold reason and clock tick (to publish in that order).
        """
        arm, clock = self.arm, self.clock
        t_n = clock.start(n)
        plan = self.adoption.lockstep(received, n)
        if plan is not None:
            arm.adopt(plan, stamp=clock.received_at(plan.tick))
        if received.occupancy_tick >= 0:
            arm.note_occupancy(clock.received_at(received.occupancy_tick))
        reason = arm.stale_reason(t_n)
        out = StepOutcome(n, reason)
        for i in range(clock.substeps):
            arm.step(clock.h, hold_reason=reason)
            arm.t = clock.substep_end(n, i)
            out.states.append(arm.state(n, arm.t))
        out.clock = ClockTick(stamp=t_n, tick=n, period=clock.period)
        out.goal, out.reached = arm.goal, arm.reached
        return out

    def finish(self, n: int, received: Received | None = None) -> StepOutcome:
        """Step n after the last replanning step: the rest of the adopted plan, no hold, no tick.

        The paper authors' protocol executes the rest of the best path once the replanning steps are over
        (``ExecutorConfig.finish_path``): the first such step adopts the last step's plan from ``received`` (as
        :meth:`step` would), the later ones none. The states of this step carry tick n; ``clock`` stays None.
        """
        arm, clock = self.arm, self.clock
        plan = self.adoption.lockstep(received, n) if received is not None else None
        if plan is not None:
            arm.adopt(plan, stamp=clock.received_at(plan.tick))
        out = StepOutcome(n, "")
        for i in range(clock.substeps):
            if arm.remaining <= 0.0:
                break
            arm.step(clock.h, hold_reason="")
            arm.t = clock.substep_end(n, i)
            out.states.append(arm.state(n, arm.t))
        out.goal, out.reached = arm.goal, arm.reached
        return out
