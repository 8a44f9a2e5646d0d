"""Lock-step rules without Zenoh: the clock, plan adoption, the per-step hold, the path pace (the master)."""

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
)
from shared.protocol import ClockTick, Plan

NAMES = ("j0", "j1")
LIMITS = ArmLimits(NAMES, np.array([-1.0, -1.0]), np.array([1.0, 1.0]), np.array([1.0, 1.0]))
CLOCK = StepClock(period=0.2, substeps=4)


def plan(tick: int, goal: float = 0.5) -> Plan:
    traj = np.stack([np.linspace([0.0, 0.0], [goal, goal], 11)]).astype(np.float32)
    zero = np.zeros(1)
    return Plan(stamp=tick * 0.2, tick=tick, step=tick, goal_names=["g"], joint_names=list(NAMES), dt=0.1, chosen=0,
                planning_ms=1.0, occupancy_tick=tick - 1, occupancy_index=0, trajectories=traj,
                cost_smoothness=zero, cost_obstacle=zero, cost_human=zero, cost_total=zero, valid=np.ones(1, bool))


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
    idle: list[bool] = []  # per call: whether it ran under the inbox's lock (it blocked the delivering thread)
    threading.Timer(0.25, inbox.put_plan, (plan(0),)).start()
    assert inbox.wait_plan(0, timeout=30.0, stop=stop, idle=lambda: idle.append(inbox._cond._is_owned()))
    assert inbox.latest().seq == 1 and idle and not any(idle)
    stop.set()
    assert not inbox.wait_plan(5, timeout=30.0, stop=stop)  # stopped: no wait
    inbox.put_occupancy(3, 1.0)
    inbox.put_occupancy(2, 2.0)  # an older tick arriving late does not go back
    assert inbox.latest().occupancy_tick == 3 and inbox.latest().occupancy_time == 2.0


def test_path_pace_advances_the_stated_length_per_step_and_finishes_the_path() -> None:
    # plan(0): a straight line from (0, 0) to (0.5, 0.5), length 0.5 sqrt(2) = 0.7071, timed 1 s at dt 0.1
    core = ExecutorCore(LIMITS, np.zeros(2), ExecutorConfig(state_rate_hz=20.0, step_period_s=0.2,
                                                            path_per_step=0.1, stale_limit_s=10.0))
    master = LockstepMaster(core, CLOCK)

    def feed(n: int, inbox: PlanInbox) -> None:
        if n == 1:
            inbox.put_plan(plan(0))
            inbox.put_occupancy(0, arrival=0.0)

    steps = run_steps(master, PlanInbox(), 4, feed)
    assert steps[0].held and not steps[1].held
    moved = [np.linalg.norm(s.states[-1].q) for s in steps]  # distance from the start along the straight line
    np.testing.assert_allclose(moved, [0.0, 0.1, 0.2, 0.3], atol=1e-9)  # 0.1 per step, whatever dt says
    np.testing.assert_allclose(np.linalg.norm(steps[1].states[0].q), 0.025, atol=1e-9)  # a quarter per substep
    assert core.remaining == pytest.approx(0.5 * np.sqrt(2) - 0.3)
    # after the last step: the rest of the path at the same pace, no clock tick, no new plan
    tail = []
    n = 4
    while core.remaining > 0:
        tail.append(master.finish(n))
        n += 1
    assert len(tail) == 5  # 0.407 left at 0.1 per step
    assert all(s.clock is None and not s.held for s in tail)
    assert [m.tick for m in tail[0].states] == [4] * 4
    np.testing.assert_allclose(tail[-1].states[-1].q, [0.5, 0.5], atol=1e-9)
    assert tail[-1].reached and len(tail[-1].states) < 4  # it stops at the end of the path


def test_the_rest_of_the_path_is_the_last_steps_plan() -> None:
    core = ExecutorCore(LIMITS, np.zeros(2), ExecutorConfig(state_rate_hz=20.0, step_period_s=0.2,
                                                            path_per_step=0.1, stale_limit_s=10.0))
    master, inbox = LockstepMaster(core, CLOCK), PlanInbox()
    inbox.put_plan(plan(0))
    inbox.put_occupancy(0, arrival=0.0)
    master.step(0, inbox.latest())
    master.step(1, inbox.latest())  # plan 0 adopted: towards (0.5, 0.5)
    here = core.q.copy()
    last = plan(1)
    last.trajectories[0] = np.linspace(here, [0.5, -0.2], 11).astype(np.float32)  # the last step re-planned
    inbox.put_plan(last)
    n = 2
    while n == 2 or core.remaining > 0:
        master.finish(n, inbox.latest() if n == 2 else None)
        n += 1
    np.testing.assert_allclose(core.q, [0.5, -0.2], atol=1e-6)  # the newest plan's goal, not plan 0's


def test_the_executor_waits_for_the_prediction_of_a_tick_unless_the_human_has_ended() -> None:
    """Plan n and the grid of tick n are made at once: which reached the executor first decided whether step n+1
    held (the grid's age), so the same seed could give another run."""
    inbox, stop = PlanInbox(), threading.Event()
    assert not inbox.wait_occupancy(3, timeout=0.01, stop=stop)
    threading.Timer(0.05, inbox.put_occupancy, (3, 1.0)).start()
    assert inbox.wait_occupancy(3, timeout=30.0, stop=stop)
    assert not inbox.wait_occupancy(4, timeout=0.01, stop=stop)
    inbox.put_marker("end", 3)  # the demonstration's last pose was of tick 3: no grid of tick 4 will come
    assert inbox.wait_occupancy(4, timeout=30.0, stop=stop) and inbox.wait_occupancy(9, timeout=30.0, stop=stop)
    assert inbox.wait_occupancy(3, timeout=30.0, stop=stop)
    inbox.put_marker("start", 5)  # another demonstration: its grids are awaited again
    assert not inbox.wait_occupancy(6, timeout=0.01, stop=stop)
