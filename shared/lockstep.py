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
* the replayer publishes its poses of tick n on ClockTick n, each tick once and in order (:class:`TickOrder`);
* the planner plans tick n from the last robot state of tick n (where plan n starts) and the
  prediction of tick n-1 (:class:`TickInbox`).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from shared.protocol import ClockTick, DemoMarker, OccupancyGrid, Plan, RobotState

__all__ = ["StepClock", "Received", "PlanInbox", "Adoption", "SimulatedArm", "StepOutcome", "LockstepMaster",
           "TickQueue", "TickOrder", "PlanningInputs", "TickInbox", "FIRST_PLAN"]

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

    def latest(self) -> Received:
        """What has arrived so far."""
        with self._cond:
            return self._now

    def wait_plan(self, tick: int, timeout: float, stop: threading.Event,
                  idle: Callable[[], None] | None = None) -> bool:
        """Whether a plan of ``tick`` or later arrived within ``timeout`` wall s (``stop`` ends the wait).

        ``idle`` is called about every 0.1 s while waiting (e.g. to flush a log).
        """
        deadline = time.monotonic() + timeout
        with self._cond:
            while not stop.is_set():
                if self._now.plan is not None and self._now.plan.tick >= tick:
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.1))
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


# ----------------------------------------------------------------------------------------------
# the clock's followers


class TickQueue:
    """Clock ticks in arrival order, handed to the service's loop one at a time (``put`` as they arrive)."""

    def __init__(self) -> None:
        self._q: queue.Queue[ClockTick] = queue.Queue()
        self.put = self._q.put

    def get(self, timeout: float) -> ClockTick | None:
        """The next tick, or None after ``timeout`` seconds."""
        try:
            return self._q.get(timeout=timeout)
        except queue.Empty:
            return None


class TickOrder:
    """Each tick once and in order (the replayer's rule): a repeated or older tick is ignored, a gap reported."""

    def __init__(self) -> None:
        self.last = -1

    def accept(self, tick: int) -> tuple[bool, str]:
        """Whether to act on ``tick``, and what to report ("" when all is in order)."""
        if tick <= self.last:
            return False, f"ignoring clock tick {tick} (already at tick {self.last})"
        note = f"clock jumped from tick {self.last} to {tick}" if tick != self.last + 1 and self.last >= 0 else ""
        self.last = tick
        return True, note


@dataclass(frozen=True)
class PlanningInputs:
    """What the planner plans tick n from.

    Attributes:
        tick: ClockTick n.
        state: The last RobotState of tick n (where plan n starts), or None if it never came.
        occupancy: The prediction of tick n-1 (or the newest earlier one after the timeout; None at tick 0).
        expected_tick: The tick of the prediction to use (n-1, or the demonstration's last pose's tick
            once it ended; -1 at tick 0).
    """

    tick: ClockTick
    state: RobotState | None
    occupancy: OccupancyGrid | None
    expected_tick: int

    @property
    def prediction_missing(self) -> bool:
        """Whether the prediction to use did not arrive in time (the planner uses ``occupancy`` instead)."""
        return self.tick.tick > 0 and (self.occupancy is None or self.occupancy.tick != self.expected_tick)


class TickInbox:
    """The planner's inbox: clock ticks, and robot states and final occupancy grids by tick, with waiting.

    Args:
        keep: Ticks of states and grids kept (the oldest are dropped).
    """

    def __init__(self, keep: int = 8) -> None:
        self.cond = threading.Condition()
        self.ticks = TickQueue()
        self.states: dict[int, RobotState] = {}
        self.occupancy: dict[int, OccupancyGrid] = {}
        self.end_tick: int | None = None  # tick of the observed demonstration's last pose, once it ended
        self.keep = keep

    def _trim(self, d: dict[int, object]) -> None:
        while len(d) > self.keep:
            d.pop(min(d))

    def add_tick(self, msg: ClockTick) -> None:
        """A clock tick arrived."""
        self.ticks.put(msg)

    def add_state(self, msg: RobotState) -> None:
        """A robot state arrived; the latest-stamped one of each tick is kept."""
        with self.cond:
            old = self.states.get(msg.tick)
            if old is None or msg.stamp >= old.stamp:
                self.states[msg.tick] = msg
                self._trim(self.states)
            self.cond.notify_all()

    def add_occupancy(self, msg: OccupancyGrid) -> None:
        """An occupancy grid arrived; only a tick's final grid (``tick_last``) is kept."""
        if not msg.tick_last:
            return
        with self.cond:
            self.occupancy[msg.tick] = msg
            self._trim(self.occupancy)
            self.cond.notify_all()

    def add_marker(self, msg: DemoMarker) -> None:
        """A demonstration marker arrived (its end carries the tick of the last pose)."""
        with self.cond:
            self.end_tick = msg.tick if msg.event == "end" else None
            self.cond.notify_all()

    def wait_state(self, tick: int, stamp: float, timeout: float) -> RobotState | None:
        """The state of ``tick`` stamped at least ``stamp`` (else the newest of that tick after the timeout)."""
        with self.cond:
            self.cond.wait_for(lambda: tick in self.states and self.states[tick].stamp >= stamp - 1e-9, timeout)
            return self.states.get(tick)

    def wait_occupancy(self, tick: int, timeout: float) -> OccupancyGrid | None:
        """The final grid of ``tick``, else the newest final grid of an earlier tick after the timeout.

        Once the observed demonstration has ended (its end marker carries the tick of its last pose),
        no grid comes after that tick: the grid of the last pose's tick is the prediction to use.
        """

        def target() -> int:
            return tick if self.end_tick is None else min(tick, self.end_tick)

        with self.cond:
            if self.cond.wait_for(lambda: target() in self.occupancy, timeout):
                return self.occupancy[target()]
            earlier = [t for t in self.occupancy if t < tick]
            return self.occupancy[max(earlier)] if earlier else None

    def inputs(self, tick: ClockTick, timeout: float) -> PlanningInputs:
        """Wait (at most ``timeout`` s each) for the state and the prediction tick n is planned from.

        The state is the last one of tick n (stamp ``t_n + P``); without it there is nothing to plan
        from and the prediction is not awaited.
        """
        state = self.wait_state(tick.tick, tick.stamp + tick.period, timeout)
        if state is None:
            return PlanningInputs(tick, None, None, tick.tick - 1)
        occ = self.wait_occupancy(tick.tick - 1, timeout) if tick.tick > 0 else None
        end = self.end_tick
        expected = tick.tick - 1 if end is None else min(tick.tick - 1, end)
        return PlanningInputs(tick, state, occ, expected)
