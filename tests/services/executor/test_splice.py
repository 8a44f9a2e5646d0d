"""Real time: a plan that starts ahead of the arm is spliced at its start (the arm goes on along its reference to it),
one that starts elsewhere is led in at its own pace; neither drives the arm at its velocity limits."""

from __future__ import annotations

import numpy as np
import pytest

from services.executor.core import ExecutorConfig, ExecutorCore
from services.executor.realtime import advance
from services.executor.reference import Reference
from services.executor.splice import pace
from services.ros2.arm import Ros2Arm
from shared.protocol import Plan
from tests.services.executor.test_core import LIMITS, make_plan
from tests.services.ros2.test_arm import LIMITS as ARM_LIMITS
from tests.services.ros2.test_arm import NAMES as ARM_NAMES
from tests.services.ros2.test_arm import FakeRobot

SHARE = 0.1  # the demo's plans are timed at 0.1 of the velocity limits


def paced(start: np.ndarray, goal: np.ndarray, limits: np.ndarray = LIMITS.velocity, **kw: object) -> Plan:
    """A straight plan from ``start`` to ``goal`` whose fastest joint moves at SHARE of its limit."""
    dt = float(np.max(np.abs(goal - start) / 20 / (SHARE * limits)))
    return make_plan(start, [goal], t=21, dt=dt, **kw)


def ref_of(plan: Plan) -> Reference:
    return Reference(plan.trajectories[plan.chosen].astype(np.float64), plan.dt)


def shares(core: ExecutorCore, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Step as the real-time loop does for ``seconds``: the configurations, and each state's fastest |qd| / limit."""
    qs, fast = [], []
    for _ in range(round(seconds / 0.02)):
        advance(core, 0.02, 0.04)
        qs.append(core.q.copy())
        fast.append(float(np.max(np.abs(core.qd) / LIMITS.velocity)))
    return np.array(qs), np.array(fast)


def off_paths(qs: np.ndarray, *refs: Reference) -> float:
    """How far the configurations ``qs`` ``(N, D)`` come off the paths of ``refs`` (each one's nearest)."""
    return max(min(float(np.linalg.norm(r.at(r.project(q, 0.0, r.duration)) - q)) for r in refs) for q in qs)


def _following(path_per_step: float = 0.0, stale_limit_s: float = 10.0) -> tuple[ExecutorCore, Reference]:
    """An arm 0.5 s along a plan at SHARE of its limits (j0, j1 at once), in real time."""
    cfg = ExecutorConfig(mode="realtime", stale_limit_s=stale_limit_s, require_occupancy=False,
                         path_per_step=path_per_step)
    core = ExecutorCore(LIMITS, np.zeros(3), cfg)
    first = paced(np.zeros(3), np.array([0.1, 0.2, 0.0]))
    core.adopt(first)
    advance(core, 0.5, 0.02)
    return core, ref_of(first)


@pytest.mark.parametrize("path_per_step", [0.0, 0.02])
def test_a_plan_that_starts_ahead_of_the_arm_is_spliced_at_its_start_not_raced_to(path_per_step: float) -> None:
    """The planner's lookahead put waypoint 0 0.3 s on along the arm's plan and the plan came at once: the arm went
    straight to it at its velocity limits (1.0 of them for a state, the plan's pace 0.1); now it goes on along its
    reference to waypoint 0 and along the new plan from there, at the pace it had."""
    core, first = _following(path_per_step)
    plan = paced(first.at(0.8), np.array([0.05, 0.35, 0.0]), chosen=0)
    new, here = ref_of(plan), core.q.copy()
    core.adopt(plan)
    assert core.taken == "spliced" and core.plan is plan and core.goal == 0  # the goal is the new plan's at once
    qs, fast = shares(core, 4.0)
    speeds = np.linalg.norm(np.diff(np.vstack([here, qs]), axis=0), axis=1) / 0.02
    if path_per_step == 0.0:  # the plan's own pace; on the new plan 0.3 s on, in step with its clock
        assert fast.max() <= 1.05 * pace(new, LIMITS.velocity) and pace(new, LIMITS.velocity) == pytest.approx(SHARE)
        for i in range(20, len(qs), 7):
            np.testing.assert_allclose(qs[i], new.at((i + 1) * 0.02 - 0.3), atol=1e-9)
    else:  # the paper authors' pace: path_per_step per period, before as after
        assert speeds.max() <= 1.05 * path_per_step / core.config.step_period_s, speeds.max()
    assert off_paths(qs, first, new) < 1e-7  # along its plan to waypoint 0, then the new plan: no short cut
    assert core.reached and np.allclose(core.q, new.goal, atol=1e-9)


def test_plans_that_keep_coming_before_the_arm_reaches_the_last_one_s_start_are_spliced_on_each_other() -> None:
    """The planner replans every 0.2 s, each plan from 0.3 s along its previous one: each starts on the reference
    the arm is following (the rest of the old plan, then the plan it has not reached yet)."""
    core, ref = _following()
    offset, fastest = 0.5, []
    for k in range(6):
        goal = np.array([0.1 - 0.02 * k, 0.2 + 0.03 * k, 0.0])
        plan = paced(ref.at(offset + 0.3), goal)
        core.adopt(plan)
        assert core.taken == "spliced", k
        ref, offset = ref_of(plan), -0.3 + 0.2  # the arm is 0.2 s into the lead when the next plan comes
        fastest.append(shares(core, 0.2)[1].max())
    assert max(fastest) <= 1.05 * SHARE, fastest


@pytest.mark.parametrize("stale_limit_s, share", [(10.0, SHARE), (0.3, 0.05 / 0.3)])
def test_a_plan_that_starts_off_the_arm_s_path_is_led_in_at_its_own_pace(stale_limit_s: float, share: float) -> None:
    """Waypoint 0 0.05 rad off the path on j1 (beyond goal_tolerance): the arm went there at its limit (1.0 of it);
    now at the plan's pace (0.5 s), or as fast as arriving within stale_limit_s needs (0.3 s: 1/6 of it)."""
    core, _ = _following(stale_limit_s=stale_limit_s)  # (held after 0.3 s with a stale limit of 0.3 s)
    plan = paced(core.q + np.array([0.0, 0.05, 0.0]), np.array([0.15, 0.3, 0.0]))
    new = ref_of(plan)
    lead = Reference(np.vstack([core.q, new.waypoints[0]]), 1.0)
    core.adopt(plan)
    assert core.taken == "led in"
    qs, fast = shares(core, 0.6)
    assert fast.max() <= 1.05 * share, fast.max()
    assert off_paths(qs, lead, new) < 1e-9 and off_paths(qs[-5:], new) < 1e-9  # straight to waypoint 0, then on


@pytest.mark.parametrize("path_per_step", [0.0, 0.02])
def test_a_late_plan_off_the_arm_s_path_is_joined_at_its_pace_not_raced_to(path_per_step: float) -> None:
    """A plan that began 0.2 s behind the arm and 0.045 rad off its path (a late plan that leaves the path): the arm
    closed the gap to the plan's nearest point at its velocity limit (1.0 of it); now it goes straight to the plan's
    next waypoint at the plan's own pace, then along the plan."""
    core, first = _following(path_per_step)
    off = np.array([0.04, -0.02, 0.0])  # across the arm's path (j0, j1 at 1 : 2)
    plan = paced(first.at(0.3) + off, np.array([0.1, 0.2, 0.0]) + 1.5 * off)
    new, here = ref_of(plan), core.q.copy()
    core.adopt(plan)
    assert core.taken == "joined" and core.goal == 0
    qs, fast = shares(core, 3.0)
    if path_per_step == 0.0:
        assert fast.max() <= 1.05 * SHARE, fast.max()
    else:
        speeds = np.linalg.norm(np.diff(np.vstack([here, qs]), axis=0), axis=1) / 0.02
        assert speeds.max() <= 1.05 * path_per_step / core.config.step_period_s, speeds.max()
    nxt = int(new.nearest(here, new.duration) / new.dt) + 1  # the plan's waypoint after its point nearest the arm
    lead = Reference(np.vstack([here, new.waypoints[nxt]]), 1.0)
    assert off_paths(qs, lead, new) < 1e-6  # straight to that waypoint, then along the plan (float32 plans)
    assert core.reached and np.allclose(core.q, new.goal, atol=1e-9)


def test_a_late_plan_through_the_arm_is_joined_where_the_arm_is() -> None:
    """On the arm's path (a late plan along the same line): joined at the arm's point, no lead."""
    core, first = _following()
    plan = paced(first.at(0.3), first.at(0.3) + 2 * (first.goal - first.at(0.3)))
    core.adopt(plan)
    assert core.taken == "joined" and core.reference.waypoints.shape == plan.trajectories[0].shape
    np.testing.assert_allclose(core.reference.at(core.tau), core.q, atol=1e-9)


class RealTimeRobot(FakeRobot):
    """A command arrives a state period after the state it was made from, as in the real-time loop."""

    def send(self, positions: np.ndarray, times: np.ndarray) -> None:
        self.sent.append((positions, times))
        self.arm.command(self.arm.t + 0.02, [0, 1], positions, times)


def test_a_ros2_robot_is_sent_the_rest_of_its_reference_then_the_early_plan_once() -> None:
    """Ros2Arm adopts as the core does: one command of the splice, timed at the plans' pace."""
    robot = RealTimeRobot(np.zeros(2))
    arm = Ros2Arm(ARM_LIMITS, np.zeros(2), ExecutorConfig(mode="realtime", stale_limit_s=10.0,
                                                          require_occupancy=False), robot)
    first = paced(np.zeros(2), np.array([0.4, 0.6]), ARM_LIMITS.velocity, names=ARM_NAMES)
    arm.adopt(first)
    for _ in range(25):
        arm.step(0.02)
    plan = paced(ref_of(first).at(0.8), np.array([0.1, 1.0]), ARM_LIMITS.velocity, names=ARM_NAMES, tick=1)
    arm.adopt(plan)
    assert arm.taken == "spliced"
    speeds = []
    for _ in range(250):
        q = robot.arm.q.copy()
        arm.step(0.02)
        speeds.append(np.max(np.abs(robot.arm.q - q) / 0.02 / ARM_LIMITS.velocity))
    assert len(robot.sent) == 2 and max(speeds) <= 1.05 * SHARE, max(speeds)  # each plan once, no rush
    np.testing.assert_allclose(robot.arm.q, [0.1, 1.0], atol=1e-9)
