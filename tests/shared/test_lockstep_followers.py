"""The clock's followers without Zenoh: each tick of the run once and in turn, the planner's tick inbox."""

from __future__ import annotations

import threading
import time

import numpy as np

from shared.lockstep_followers import STOP_SLICE_S, TickInbox, TickOrder, TickVerdict
from shared.protocol import ClockTick, DemoMarker, OccupancyGrid, RobotState
from shared.protocol.schema import REASONS

NAMES = ("j0", "j1")


def grid(tick: int, last: bool = True) -> OccupancyGrid:
    return OccupancyGrid.from_dense(np.zeros((2, 2, 2), np.float32), np.zeros(3), 0.1, stamp=0.0, tick=tick,
                                    tick_last=last, demo_id=0, index=tick, method="prediction")


def state(tick: int, stamp: float) -> RobotState:
    return RobotState(stamp=stamp, tick=tick, joint_names=list(NAMES), goal=-1, reached=False, holding=True,
                      reason="", q=np.zeros(2), qd=np.zeros(2))


def test_tick_order_takes_each_tick_once_in_turn() -> None:
    """A jump ahead is refused now (it was taken, reported): the executor ticks each in turn, and one forged tick far
    ahead (--security off) made every later tick of the run "older": the replayer fell silent for the rest of it."""
    order = TickOrder()
    assert order.accept(0, 0.2) == TickVerdict(True)
    assert order.accept(1, 0.2) == TickVerdict(True)
    assert order.accept(1, 0.2) == TickVerdict(False, "clock tick 1 not after the run's last, 1", "tick-order")
    ahead = order.accept(1_000_000, 0.2)
    assert not ahead.take and ahead.reason == "stamp-future" and "1000000 ahead of the run's next, 2" in ahead.note
    assert order.accept(3, 0.2).reason == "stamp-future"  # a tick slightly ahead too
    assert order.accept(2, 50.0) == TickVerdict(False, "clock tick 2: period 50 s, this run's is 0.2 s", "mismatch")
    stale = order.accept(0, 0.2)  # tick 0 mid-run with the executor still there
    assert not stale.take and stale.reason == "tick-order" and "once the executor has left" in stale.note
    assert order.accept(2, 0.2) == TickVerdict(True) and order.last == 2  # the run goes on untouched
    assert all(r in REASONS for r in ("tick-order", "stamp-future", "mismatch"))


def test_a_late_join_is_taken_and_said() -> None:
    """A replayer started after the executor's first ticks started its stream at tick 7 without a word."""
    order = TickOrder()
    first = order.accept(7, 0.2)
    assert first.take and not first.new_run and "joined the clock at tick 7" in first.note
    assert order.accept(8, 0.2) == TickVerdict(True)


def test_tick_inbox_pairs_a_tick_with_its_state_and_the_previous_prediction() -> None:
    inbox = TickInbox(keep=3)
    tick0, tick2 = ClockTick(stamp=0.0, tick=0, period=0.2), ClockTick(stamp=0.4, tick=2, period=0.2)
    inbox.add_tick(tick0)
    assert inbox.ticks.get(timeout=1.0) == tick0 and inbox.ticks.get(timeout=0.0) is None
    inbox.add_state(state(0, 0.2))
    got = inbox.inputs(tick0, timeout=0.0)
    assert got.state.stamp == 0.2 and got.occupancy is None and not got.prediction_missing
    inbox.add_state(state(2, 0.6))
    inbox.add_state(state(2, 0.5))  # an earlier state of the tick arriving late is not kept
    inbox.add_occupancy(grid(1, last=False))  # only a tick's final grid counts
    got = inbox.inputs(tick2, timeout=0.0)
    assert got.state.stamp == 0.6 and got.occupancy is None and got.prediction_missing
    inbox.add_occupancy(grid(0))
    got = inbox.inputs(tick2, timeout=0.0)
    assert got.occupancy.tick == 0 and got.prediction_missing  # the newest earlier grid, reported
    inbox.add_occupancy(grid(1))
    got = inbox.inputs(tick2, timeout=0.0)
    assert got.occupancy.tick == 1 and not got.prediction_missing


def test_after_the_demonstration_ends_its_last_prediction_is_the_one_to_use() -> None:
    inbox = TickInbox()
    inbox.add_occupancy(grid(1))
    inbox.add_marker(DemoMarker(stamp=0.2, tick=1, demo_id=0, event="end", true_class=0, class_name="c",
                                n_samples=5))
    tick5 = ClockTick(stamp=1.0, tick=5, period=0.2)
    inbox.add_state(state(5, 1.2))
    got = inbox.inputs(tick5, timeout=0.0)
    assert got.expected_tick == 1 and got.occupancy.tick == 1 and not got.prediction_missing


def test_no_state_means_no_wait_for_the_prediction() -> None:
    got = TickInbox().inputs(ClockTick(stamp=0.2, tick=1, period=0.2), timeout=0.0)
    assert got.state is None and got.occupancy is None


def test_inboxes_keep_only_recent_ticks() -> None:
    inbox = TickInbox(keep=2)
    for t in range(4):
        inbox.add_state(state(t, t * 0.2))
        inbox.add_occupancy(grid(t))
    assert sorted(inbox.states) == [2, 3] and sorted(inbox.occupancy) == [2, 3]


def test_a_restarted_clock_is_a_new_run_for_the_replayer() -> None:
    """Tick 0 after a later tick: the replayer ignored every tick of the new run up to the old run's last. Now the
    executor's token must have gone first (its process ended with it): any tick 0 mid-run was taken as a new run."""
    order = TickOrder()
    for t in range(20):
        order.accept(t, 0.2)
    order.executor_gone()
    got = order.accept(0, 0.5)  # a new run may have another period
    assert got.take and got.new_run and "starts over" in got.note
    assert order.accept(1, 0.5) == TickVerdict(True)
    assert order.accept(0, 0.5).reason == "tick-order"  # taken once: the token has to go again


def test_after_a_lost_link_the_run_resumes_past_the_missed_ticks() -> None:
    """The ticks sent while the link was down are lost; the executor's token went with the link: a later tick of the
    same period resumes the run, an older one or another period is still refused."""
    order = TickOrder()
    for t in range(5):
        order.accept(t, 0.2)
    order.executor_gone()
    assert order.accept(3, 0.2).reason == "tick-order"
    assert order.accept(9, 0.5).reason == "mismatch"
    got = order.accept(9, 0.2)
    assert got.take and not got.new_run and "resumed at tick 9 after tick 4" in got.note
    assert order.accept(11, 0.2).reason == "stamp-future"  # the token back in place: each in turn again


def test_a_new_run_does_not_get_the_last_runs_states_and_grids() -> None:
    """A planner outliving a run kept its inbox: the new run's low ticks were dropped at once (the lowest tick went
    first) and its later ticks were answered with the old run's states and grids."""
    inbox = TickInbox(keep=8)
    for t in range(20):  # run A
        inbox.add_state(state(t, (t + 1) * 0.2))
        inbox.add_occupancy(grid(t))
    inbox.add_state(state(-1, 0.0))  # run B: the executor's initial state, then tick 0
    inbox.add_state(state(0, 0.2))
    assert sorted(inbox.states) == [-1, 0] and inbox.occupancy == {}
    got = inbox.inputs(ClockTick(stamp=2.6, tick=13, period=0.2), timeout=0.0)
    assert got.state is None and got.occupancy is None  # nothing of run A answers run B's tick 13
    for t in range(1, 12):  # run B goes on: its own ticks are kept
        inbox.add_state(state(t, (t + 1) * 0.2))
    assert sorted(inbox.states) == list(range(4, 12))


def test_a_stopped_follower_stops_waiting_and_a_late_state_is_named() -> None:
    """A stopped planner went on waiting its whole input timeout (60 s in the experiments), then planned a step on
    the Planner the next run had already reset."""
    inbox, stop = TickInbox(), threading.Event()
    tick = ClockTick(stamp=1.0, tick=5, period=0.2)
    threading.Timer(0.2, stop.set).start()
    started = time.monotonic()
    assert inbox.inputs(tick, timeout=30.0, stop=stop).state is None
    assert time.monotonic() - started < 0.2 + 5 * STOP_SLICE_S + 2.0  # a slice after the stop, not 30 s
    inbox.add_state(state(5, 1.1))  # tick 5 ends at 1.2: the newest of the tick, but not its last
    inbox.add_occupancy(grid(4))
    got = inbox.inputs(tick, timeout=0.0)
    assert got.state_late and not got.prediction_missing
    inbox.add_state(state(5, 1.2))
    assert not inbox.inputs(tick, timeout=0.0).state_late
