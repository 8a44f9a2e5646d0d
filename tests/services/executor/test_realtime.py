"""The real-time loop's stepping: a stall of the loop is walked along the path, judged for staleness as it goes; each
state is stamped with the wall time its configuration is for."""

from __future__ import annotations

import threading
import time

import numpy as np

from services.executor.core import ExecutorConfig, ExecutorCore
from services.executor.realtime import advance, run_realtime
from services.executor.reference import Reference
from services.executor.result import ExecutorResult
from shared.lockstep import PlanInbox
from shared.protocol import RobotState
from tests.services.executor.test_core import LIMITS, make_plan


def _l_shaped_core(stale_limit_s: float, guard=None) -> tuple[ExecutorCore, Reference]:
    """An arm on an L: j0 first (0 -> 0.4), then j1 (0 -> 0.8), 0.1 s per waypoint, well within the limits."""
    leg = np.linspace(0.0, 1.0, 11)[1:]
    path = np.vstack([np.zeros(3), np.c_[0.4 * leg, 0 * leg, 0 * leg], np.c_[0.4 + 0 * leg, 0.8 * leg, 0 * leg]])
    plan = make_plan(np.zeros(3), [np.zeros(3)], t=2)
    plan.trajectories = path[None].astype(np.float32)
    core = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(stale_limit_s=stale_limit_s, require_occupancy=False),
                        guard=guard)
    core.adopt(plan)
    return core, Reference(path, plan.dt)


def test_a_stall_is_walked_along_the_path_and_the_guard_asked_on_it() -> None:
    """The separation guard judges each move: one move of the whole gap was a chord through the L's corner."""
    asked: list[tuple[np.ndarray, np.ndarray]] = []

    def guard(q: np.ndarray, q_next: np.ndarray) -> str:
        asked.append((q.copy(), q_next.copy()))
        return ""

    core, ref = _l_shaped_core(10.0, guard)
    advance(core, 1.6, 0.04)  # the loop was away 1.6 s: the reference's point at 1.6 s, reached along the L
    np.testing.assert_allclose(core.q, ref.at(1.6), atol=1e-9)
    assert abs(core.t - 1.6) < 1e-9 and len(asked) == 40
    on_l = [bool(np.isclose(b[1], 0.0) or np.isclose(a[0], 0.4)) for a, b in asked]  # each move along one leg
    assert all(on_l)
    asked.clear()
    one, _ = _l_shaped_core(10.0, guard)
    one.step(1.6)  # the old loop: one move from the start to 1.6 s on, across the corner
    (a, b), = asked
    assert np.allclose(a, 0.0) and np.allclose(b, ref.at(1.6))  # j0 and j1 at once: off the path between


def test_a_stall_longer_than_the_stale_limit_holds_once_the_plan_is_stale() -> None:
    core, ref = _l_shaped_core(stale_limit_s=0.5)
    advance(core, 2.0, 0.04)  # a 2 s stall on a plan adopted at its start: it moved 0.5 s of it, then held
    assert core.holding and core.reason.startswith("plan is ")
    np.testing.assert_allclose(core.q, ref.at(0.52), atol=1e-9)  # the step starting at 0.48 s, the last not stale
    assert abs(core.t - 2.0) < 1e-9


def test_the_guard_is_not_asked_while_the_arm_is_at_rest() -> None:
    """At the goal the arm stays where it is: the guard ran its forward kinematics on every state anyway (50 of 50)."""
    calls: list[int] = []
    core, ref = _l_shaped_core(100.0, lambda q, q_next: calls.append(1) or "")
    advance(core, 2.2, 0.04)  # along the L (2 s) to the goal: the guard asked on each move
    moving = len(calls)
    assert 50 <= moving <= 55 and core.reached and np.allclose(core.q, ref.at(2.0))
    advance(core, 1.0, 0.04)  # at the goal: nothing to ask
    assert len(calls) == moving


def _late_plan(mode: str, path_per_step: float = 0.0) -> tuple[ExecutorCore, float, list[float]]:
    """An arm 0.5 s along a straight plan gets the same line to the goal from where it was 0.2 s before.

    Returns the core, where j0 was when the late plan came, and j0's velocity at each of the next 8 states.
    """
    cfg = ExecutorConfig(mode=mode, stale_limit_s=10.0, require_occupancy=False, path_per_step=path_per_step)
    core = ExecutorCore(LIMITS, np.zeros(3), cfg)
    goal = np.array([0.8, 0.4, 0.0])
    core.adopt(make_plan(np.zeros(3), [goal], t=21, dt=0.1))  # 2 s: j0 at 0.4 rad/s, within its 0.5
    advance(core, 0.5, 0.02)
    here = core.q.copy()
    core.adopt(make_plan(here - 0.2 * core.qd, [goal], t=21, dt=0.1))  # waypoint 0: 0.08 rad behind on j0
    velocities = []
    for _ in range(8):
        advance(core, 0.02, 0.04)
        velocities.append(float(core.qd[0]))
    return core, float(here[0]), velocities


def test_a_plan_that_starts_behind_the_arm_is_joined_where_the_arm_is_not_driven_back_to() -> None:
    """Real time: a plan late on its planner's lookahead begins where the robot was; from its first waypoint the arm
    was driven back at its velocity limit (-0.5 rad/s on j0 for 0.16 s, 0.08 rad) before it went on."""
    for path_per_step in (0.0, 0.05):
        core, was, velocities = _late_plan("realtime", path_per_step)
        assert min(velocities) > 0.0, velocities  # on along the path from where the arm is
        assert core.q[0] > was
    lockstep = ExecutorCore(LIMITS, np.full(3, 0.1), ExecutorConfig())
    lockstep.adopt(make_plan(np.zeros(3), [np.full(3, 0.3)], t=21, dt=0.1))
    assert lockstep.tau == 0.0  # lock-step: waypoint 0 is the arm's configuration by the protocol, runs unchanged


class _Loop:
    """What :func:`run_realtime` uses of the service: ``core``, its config, an inbox with one plan, the states out."""

    def __init__(self, core: ExecutorCore) -> None:
        self.core, self.config, self.result = core, core.config, ExecutorResult()
        self.stop, self.inbox, self.states = threading.Event(), PlanInbox(), []

    def wait_for_peers(self, presence: object) -> None:
        pass

    def publish_state(self, pub: object, state: RobotState) -> None:
        self.states.append(state)


def test_a_state_is_stamped_with_the_wall_time_its_configuration_is_for() -> None:
    """Stamped with the wall clock after the step, a state's stamp lagged its q by however long the step took (here a
    guard taking 30 ms every other step): q differenced over the stamps was off its velocity (2.28 rad/s where qd was
    about 0.2 in a review's run). Now the stamp is the run's start on the wall clock plus the core's time."""
    calls = []

    def slow_guard(q: np.ndarray, q_next: np.ndarray) -> str:
        calls.append(1)
        if len(calls) % 2:
            time.sleep(0.03)
        return ""

    cfg = ExecutorConfig(mode="realtime", steps=2, step_period_s=0.2, stale_limit_s=10.0, require_occupancy=False)
    svc = _Loop(ExecutorCore(LIMITS, np.zeros(3), cfg, guard=slow_guard))
    svc.inbox.put_plan(make_plan(np.zeros(3), [np.array([0.4, 0.2, 0.0])], t=21, dt=0.1))  # 2 s: j0 at 0.2 rad/s
    before = time.time()
    run_realtime(svc, None, None)  # type: ignore[arg-type]
    stamps = np.array([s.stamp for s in svc.states])
    qs = np.array([s.q for s in svc.states])
    assert len(stamps) >= 10 and before <= stamps[0] <= time.time()  # on the wall clock
    v = np.diff(qs[:, 0]) / np.diff(stamps)
    np.testing.assert_allclose(v, 0.2, rtol=1e-3)  # q over the stamps moves as the plan does
    np.testing.assert_allclose(qs[-1, 0], 0.2 * (stamps[-1] - stamps[0]) + qs[0, 0], atol=1e-5)
