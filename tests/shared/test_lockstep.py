"""Lock-step rules without Zenoh: the clock, plan adoption, the per-step hold, the tick inboxes."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from services.executor.core import ArmLimits, ExecutorConfig, ExecutorCore
from shared.lockstep import (
    FIRST_PLAN,
    Adoption,
    LockstepMaster,
    PlanInbox,
    Received,
    StepClock,
    TickInbox,
    TickOrder,
)
from shared.protocol import ClockTick, DemoMarker, OccupancyGrid, Plan, RobotState

NAMES = ("j0", "j1")
LIMITS = ArmLimits(NAMES, np.array([-1.0, -1.0]), np.array([1.0, 1.0]), np.array([1.0, 1.0]))
CLOCK = StepClock(period=0.2, substeps=4)


def plan(tick: int, goal: float = 0.5) -> Plan:
    traj = np.stack([np.linspace([0.0, 0.0], [goal, goal], 11)]).astype(np.float32)
    zero = np.zeros(1)
    return Plan(stamp=tick * 0.2, tick=tick, step=tick, goal_names=["g"], joint_names=list(NAMES), dt=0.1, chosen=0,
                planning_ms=1.0, occupancy_tick=tick - 1, occupancy_index=0, trajectories=traj,
                cost_smoothness=zero, cost_obstacle=zero, cost_human=zero, cost_total=zero, valid=np.ones(1, bool))


def grid(tick: int, last: bool = True) -> OccupancyGrid:
    return OccupancyGrid.from_dense(np.zeros((2, 2, 2), np.float32), np.zeros(3), 0.1, stamp=0.0, tick=tick,
                                    tick_last=last, demo_id=0, index=tick, method="prediction")


def state(tick: int, stamp: float) -> RobotState:
    return RobotState(stamp=stamp, tick=tick, joint_names=list(NAMES), goal=-1, reached=False, holding=True,
                      reason="", q=np.zeros(2), qd=np.zeros(2))


def test_clock_times_are_multiples_of_the_period() -> None:
    assert CLOCK.h == pytest.approx(0.05)
    assert CLOCK.start(3) == 3 * 0.2 and CLOCK.received_at(2) == 2 * 0.2
    assert [CLOCK.substep_end(1, i) for i in range(4)] == [0.2 + (i + 1) * (0.2 / 4) for i in range(4)]


def test_plan_of_tick_n_minus_1_is_adopted_at_step_n_once() -> None:
    adoption = Adoption()
    got = Received(plan(2), seq=1)
    assert adoption.lockstep(got, 2) is None  # plan 2 runs during step 3, not 2
    assert adoption.lockstep(got, 3) is got.plan
    assert adoption.lockstep(got, 4) is None  # already adopted
    assert adoption.lockstep(Received(plan(3), seq=2), 4).tick == 3
    assert adoption.lockstep(Received(None, 0), 5) is None
    rt = Adoption()
    assert rt.realtime(got) is got.plan and rt.realtime(got) is None


def run_steps(master: LockstepMaster, inbox: PlanInbox, n_steps: int, feed) -> list:
    out = []
    for n in range(n_steps):
        feed(n, inbox)
        out.append(master.step(n, inbox.latest()))
    return out


def test_master_holds_until_fresh_plan_and_occupancy_then_moves_and_holds_again_when_stale() -> None:
    core = ExecutorCore(LIMITS, np.zeros(2), ExecutorConfig(stale_limit_s=0.5, state_rate_hz=20.0))
    master = LockstepMaster(core, CLOCK)
    assert master.initial_state().tick == -1 and master.initial_state().stamp == 0.0

    def feed(n: int, inbox: PlanInbox) -> None:
        if n == 1:  # the plan and the grid of tick 0 arrive during step 0; then nothing more
            inbox.put_plan(plan(0))
            inbox.put_occupancy(0, arrival=123.0)

    steps = run_steps(master, PlanInbox(), 6, feed)
    assert [s.held for s in steps] == [True, False, False, True, True, True]
    assert steps[0].reason == FIRST_PLAN and not steps[0].hold_news  # the start is no news
    assert "plan is 0.60 s old" in steps[3].reason and steps[3].hold_news  # received at t = 0, now t_3 = 0.6
    for s in steps:
        assert [m.tick for m in s.states] == [s.tick] * 4
        assert [m.stamp for m in s.states] == [CLOCK.substep_end(s.tick, i) for i in range(4)]
        assert s.clock == ClockTick(stamp=CLOCK.start(s.tick), tick=s.tick, period=0.2)
    held = steps[4].states
    assert all(m.holding for m in held) and np.allclose(held[0].q, held[-1].q)
    assert not any(m.holding for m in steps[1].states)
    assert not np.allclose(steps[1].states[0].q, steps[2].states[-1].q)  # it moved in steps 1 and 2
    assert steps[2].goal == 0


def test_master_holds_without_occupancy_when_required() -> None:
    core = ExecutorCore(LIMITS, np.zeros(2), ExecutorConfig(stale_limit_s=0.5))
    master = LockstepMaster(core, CLOCK)
    inbox = PlanInbox()
    inbox.put_plan(plan(0))
    assert master.step(1, inbox.latest()).reason == "no occupancy prediction received yet"
    inbox.put_occupancy(1, arrival=0.0)
    assert master.step(2, inbox.latest()).reason == ""


def test_plan_inbox_waits_for_the_plan_of_a_tick() -> None:
    inbox, stop = PlanInbox(), threading.Event()
    assert not inbox.wait_plan(0, timeout=0.01, stop=stop)
    idle: list[int] = []
    threading.Timer(0.05, inbox.put_plan, (plan(0),)).start()
    assert inbox.wait_plan(0, timeout=30.0, stop=stop, idle=lambda: idle.append(1))
    assert inbox.latest().seq == 1 and idle
    stop.set()
    assert not inbox.wait_plan(5, timeout=30.0, stop=stop)  # stopped: no wait
    inbox.put_occupancy(3, 1.0)
    inbox.put_occupancy(2, 2.0)  # an older tick arriving late does not go back
    assert inbox.latest().occupancy_tick == 3 and inbox.latest().occupancy_time == 2.0


def test_tick_order_takes_each_tick_once_in_order() -> None:
    order = TickOrder()
    assert order.accept(0) == (True, "")
    assert order.accept(1) == (True, "")
    assert order.accept(1) == (False, "ignoring clock tick 1 (already at tick 1)")
    assert order.accept(3) == (True, "clock jumped from tick 1 to 3")
    assert order.accept(2)[0] is False


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
