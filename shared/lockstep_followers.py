"""Lock-step followers of the clock: how the replayer and the planner take ClockTicks.

The master, the executor's rules, is :mod:`shared.lockstep`.

No Zenoh here. The replayer publishes its poses of tick n on ClockTick n, each tick of the executor's run once and
in turn (:class:`TickOrder`, fed by a :class:`TickQueue`); the planner plans tick n from the last robot state of
tick n (where plan n starts) and the prediction of tick n-1 (:class:`TickInbox`).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from shared.protocol import ClockTick, DemoMarker, OccupancyGrid, RobotState

__all__ = ["TickQueue", "TickVerdict", "TickOrder", "PlanningInputs", "TickInbox", "STOP_SLICE_S"]

STOP_SLICE_S = 0.1
"""Longest a stopped follower goes on waiting for its inputs (a stopped planner once waited its whole timeout)."""


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


@dataclass(frozen=True)
class TickVerdict:
    """What :meth:`TickOrder.accept` made of a clock tick.

    Attributes:
        take: Act on the tick (publish its poses).
        note: What to log ("" when all is in order): a late join, a new run, a resumed run, or why it is refused.
        reason: Why it is refused, a key of :data:`shared.protocol.schema.REASONS` ("" when taken).
        new_run: Tick 0 of a new run after an earlier run's ticks: the stream starts over from its beginning.
    """

    take: bool
    note: str = ""
    reason: str = ""
    new_run: bool = False


class TickOrder:
    """The replayer's rule: the ticks of one executor's run, each once and in turn; anything else is refused.

    The executor ticks 0, 1, 2, ... with one period (:class:`shared.lockstep.LockstepMaster`). A follower sees
    another sequence only in three cases, all taken: its first tick may be later than 0 (it joined a run already
    going); and after the executor's liveliness token went away (:meth:`executor_gone`: its process ended, or the
    link to it went and the ticks sent meanwhile were lost), tick 0 starts a new run (any period) and a later tick
    of the same period resumes the run. Otherwise only the last tick + 1 with the same period is taken: with
    security off anyone may publish on the clock key, and one forged tick far ahead silenced the replayer for the
    rest of its run (each later tick was "older"), a forged tick 0 restarted it mid-run.

    Thread-safe: :meth:`executor_gone` is called on the transport's thread.
    """

    def __init__(self) -> None:
        self.last = -1
        self.period: float | None = None
        self._gone = False  # the executor's token went away since the last tick taken
        self._lock = threading.Lock()

    def executor_gone(self) -> None:
        """The executor's liveliness token went away: the next tick may start a new run or resume after a gap."""
        with self._lock:
            self._gone = True

    def accept(self, tick: int, period: float) -> TickVerdict:
        """Whether to act on ClockTick ``tick`` of ``period`` s, and what to report."""
        with self._lock:
            verdict = self._judge(tick, period)
            if verdict.take:
                self.last, self.period, self._gone = tick, period, False
            return verdict

    def _judge(self, tick: int, period: float) -> TickVerdict:
        last, gone = self.last, self._gone
        if self.period is None:
            return TickVerdict(True, "" if tick == 0 else f"joined the clock at tick {tick} (a run already going): "
                                                           "the stream starts from its beginning at this tick")
        if tick == 0 and gone:
            return TickVerdict(True, f"clock restarted at tick 0 after tick {last} (the executor left and a new run "
                                     "began): the stream starts over from its beginning", new_run=True)
        if period != self.period:
            return TickVerdict(False, f"clock tick {tick}: period {period:g} s, this run's is {self.period:g} s",
                               "mismatch")
        if tick == last + 1 or (gone and tick > last):
            note = f"clock resumed at tick {tick} after tick {last} (the executor's link went)" * (tick > last + 1)
            return TickVerdict(True, note)
        if tick > last:
            return TickVerdict(False, f"clock tick {tick} ahead of the run's next, {last + 1} (the executor ticks "
                                      "each in turn)", "stamp-future")
        why = "" if tick else " (a new run starts at 0 only once the executor has left)"
        return TickVerdict(False, f"clock tick {tick} not after the run's last, {last}{why}", "tick-order")


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
    def state_late(self) -> bool:
        """Whether the state is older than the end of tick n (the newest one of that tick after the timeout)."""
        return self.state is not None and self.state.stamp < self.tick.stamp + self.tick.period - 1e-9

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
        while len(d) > self.keep:  # the first received goes first: a new run's low ticks are no older than the last
            d.pop(next(iter(d)))

    def _new_run(self) -> None:
        """Forget the last run's states, grids and end (its ticks and simulated stamps are the new run's too)."""
        self.states.clear()
        self.occupancy.clear()
        self.end_tick = None

    def add_tick(self, msg: ClockTick) -> None:
        """A clock tick arrived."""
        self.ticks.put(msg)

    def add_state(self, msg: RobotState) -> None:
        """A robot state arrived; the latest-stamped one of each tick is kept.

        A state of tick 0 or -1 after later ones starts a new run (the executor started again): what the inbox
        held of the last run is forgotten, or its states and grids would answer the new run's ticks.
        """
        with self.cond:
            if msg.tick <= 0 < max(self.states, default=0):  # the first state of a new run (tick -1, then 0)
                self._new_run()
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

    def _wait_for(self, ready: Callable[[], bool], timeout: float, stop: threading.Event | None) -> bool:
        """``cond.wait_for`` (the lock held) in slices of :data:`STOP_SLICE_S`, ending early once ``stop`` is set."""
        end = time.monotonic() + timeout
        while not (done := ready()):
            left = end - time.monotonic()
            if left <= 0 or (stop is not None and stop.is_set()):
                break
            self.cond.wait(min(left, STOP_SLICE_S))
        return done

    def wait_state(self, tick: int, stamp: float, timeout: float,
                   stop: threading.Event | None = None) -> RobotState | None:
        """The state of ``tick`` stamped at least ``stamp`` (else the newest of that tick after the timeout or stop)."""
        with self.cond:
            self._wait_for(lambda: tick in self.states and self.states[tick].stamp >= stamp - 1e-9, timeout, stop)
            return self.states.get(tick)

    def wait_occupancy(self, tick: int, timeout: float, stop: threading.Event | None = None) -> OccupancyGrid | None:
        """The final grid of ``tick``, else the newest final grid of an earlier tick after the timeout (or stop).

        Once the observed demonstration has ended (its end marker carries the tick of its last pose),
        no grid comes after that tick: the grid of the last pose's tick is the prediction to use.
        """

        def target() -> int:
            return tick if self.end_tick is None else min(tick, self.end_tick)

        with self.cond:
            if self._wait_for(lambda: target() in self.occupancy, timeout, stop):
                return self.occupancy[target()]
            earlier = [t for t in self.occupancy if t < tick]
            return self.occupancy[max(earlier)] if earlier else None

    def inputs(self, tick: ClockTick, timeout: float, stop: threading.Event | None = None) -> PlanningInputs:
        """Wait (at most ``timeout`` s each, less once ``stop`` is set) for the state and the prediction of tick n.

        The state is the last one of tick n (stamp ``t_n + P``); without it there is nothing to plan
        from and the prediction is not awaited.
        """
        state = self.wait_state(tick.tick, tick.stamp + tick.period, timeout, stop)
        if state is None:
            return PlanningInputs(tick, None, None, tick.tick - 1)
        occ = self.wait_occupancy(tick.tick - 1, timeout, stop) if tick.tick > 0 else None
        end = self.end_tick
        expected = tick.tick - 1 if end is None else min(tick.tick - 1, end)
        return PlanningInputs(tick, state, occ, expected)
