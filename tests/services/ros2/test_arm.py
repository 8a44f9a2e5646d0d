"""Ros2Arm: the executor's rules driving a ROS 2 robot -- each plan sent once, a hold once per hold, the measured
state replacing the simulated one; command_points: the executor's pace within the velocity limits."""

from __future__ import annotations

import numpy as np
import pytest

from services.executor.config import ExecutorConfig
from services.executor.core import ArmLimits
from services.executor.reference import Reference
from services.ros2.arm import MIN_SEGMENT_S, Measured, Ros2Arm, command_points, hold_point, present
from services.ros2.controller import SimulatedController
from shared.lockstep import FIRST_PLAN
from tests.services.executor.test_core import make_plan

NAMES = ("j0", "j1")
LIMITS = ArmLimits(NAMES, np.array([-3.0, -3.0]), np.array([3.0, 3.0]), np.array([1.0, 2.0]))


class FakeRobot:
    """A RobotLink over a SimulatedController on the arm's clock; ``age`` is what measure reports."""

    def __init__(self, q0: np.ndarray) -> None:
        self.arm = SimulatedController(q0)
        self.sent: list[tuple[np.ndarray, np.ndarray]] = []
        self.age = 0.0

    def send(self, positions: np.ndarray, times: np.ndarray) -> None:
        self.sent.append((positions, times))
        self.arm.command(self.arm.t, [0, 1], positions, times)

    def measure(self, t: float) -> Measured:
        self.arm.advance(t)
        return Measured(self.arm.q.copy(), self.arm.qd.copy(), self.age)


def _arm(config: ExecutorConfig | None = None) -> tuple[Ros2Arm, FakeRobot]:
    robot = FakeRobot(np.zeros(2))
    return Ros2Arm(LIMITS, np.zeros(2), config or ExecutorConfig(stale_limit_s=0.5), robot), robot


def test_each_plan_is_sent_once_and_the_robot_state_is_measured() -> None:
    arm, robot = _arm(ExecutorConfig(stale_limit_s=5.0))
    arm.step(0.1)
    assert arm.reason == FIRST_PLAN and robot.sent == []  # nothing to hold before a plan
    plan = make_plan(np.zeros(2), [np.array([0.5, 1.0])], t=11, dt=0.1, names=NAMES)  # 1 s, within the limits
    arm.adopt(plan)
    for _ in range(12):
        arm.note_occupancy()
        arm.step(0.1)
    assert len(robot.sent) == 1 and arm.sent_plans == 1
    positions, times = robot.sent[0]
    assert positions.shape == (10, 2) and times[-1] == pytest.approx(1.0)  # the waypoints ahead at the plan's pace
    np.testing.assert_allclose(arm.q, [0.5, 1.0], atol=1e-9)  # where the robot is
    assert arm.reached and not arm.holding


def test_a_hold_is_sent_once_at_the_present_configuration_and_the_plan_again_on_resuming() -> None:
    arm, robot = _arm()
    arm.adopt(make_plan(np.zeros(2), [np.array([1.0, 1.0])], t=21, dt=0.1, names=NAMES))
    arm.note_occupancy()
    arm.step(0.1)
    q_then = arm.q.copy()
    for _ in range(8):  # nothing new: plan and occupancy stale after 0.5 s
        arm.step(0.1)
    assert arm.holding and "s old (limit 0.50 s)" in arm.reason
    assert len(robot.sent) == 2 and arm.sent_holds == 1
    hold, hold_time = robot.sent[1]  # one point where the arm is (a controller refuses a trajectory without points)
    assert hold.shape == (1, 2) and hold_time.tolist() == [MIN_SEGMENT_S]
    held = arm.q.copy()
    np.testing.assert_allclose(hold[0], held)
    assert np.all(held > q_then)  # it stopped where it was when told to hold, not back where it was measured
    arm.step(0.1)
    np.testing.assert_allclose(arm.q, held)  # stopped
    arm.adopt(make_plan(arm.q, [np.array([1.0, 1.0])], t=11, dt=0.1, names=NAMES))
    arm.note_occupancy()
    arm.step(0.1)
    assert not arm.holding and arm.sent_plans == 2 and len(robot.sent) == 3


def test_stale_joint_states_hold_the_robot() -> None:
    arm, robot = _arm()
    arm.adopt(make_plan(np.zeros(2), [np.array([1.0, 1.0])], t=21, dt=0.1, names=NAMES))
    arm.note_occupancy()
    robot.age = 0.8
    arm.step(0.1)  # measures the age
    arm.note_occupancy()
    arm.step(0.1)
    assert arm.holding and arm.reason == "robot's joint states are 0.80 s old (limit 0.50 s)"


def test_command_points_keep_the_pace_within_the_velocity_limits() -> None:
    ref = Reference(np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [1.2, 0.0]]), dt=0.1)
    cfg = ExecutorConfig(velocity_scale=0.5)  # joint 0 at most 0.5 rad/s
    positions, times = command_points(ref, 0.15, np.array([0.15, 0.0]), cfg, LIMITS)
    np.testing.assert_allclose(positions, [[0.2, 0.0], [1.2, 0.0]])
    np.testing.assert_allclose(times, [0.1, 0.1 + 2.0])  # 0.05 rad: 0.1 s at 0.5 rad/s; 1 rad: 2 s, not 0.1
    # the paper authors' pace: 0.1 of path length per 0.5 s step
    cfg = ExecutorConfig(path_per_step=0.1, step_period_s=0.5)
    positions, times = command_points(ref, 0.1, np.array([0.1, 0.0]), cfg, LIMITS)
    np.testing.assert_allclose(times[:1], [0.5]) and np.testing.assert_allclose(times[-1], 0.5 + 5.0)
    # past the end: the goal, at least MIN_SEGMENT_S away
    positions, times = command_points(ref, 5.0, np.array([1.2, 0.0]), ExecutorConfig(), LIMITS)
    assert positions.tolist() == [[1.2, 0.0]] and times.tolist() == [MIN_SEGMENT_S]


def test_a_continuous_joint_at_pi_is_commanded_and_timed_the_short_way() -> None:
    """The robot reports its wrist roll at +pi (+1e-4), read by the planner as -pi; the plan stays just below +pi.
    The segments were timed on the wrapped reading, a 2 pi turn: 3.48 s where 0.1 s is the pace."""
    limits = ArmLimits(("a", "roll"), np.array([-1.0, -np.pi]), np.array([1.0, np.pi]), np.array([1.0, 3.6]), ("roll",))
    ref = Reference(np.array([[0.0, 3.12], [0.02, 3.13], [0.04, 3.14]]), dt=0.1)
    positions, times = command_points(ref, 0.0, np.array([0.0, np.pi + 1e-4]), ExecutorConfig(velocity_scale=0.5),
                                      limits)
    np.testing.assert_allclose(positions[:, 1], [3.13, 3.14])  # the robot's own values, no turn round
    np.testing.assert_allclose(times, [0.1, 0.2])  # the executor's pace: 0.1 s per waypoint
    # unwrapped far from [-pi, pi): the command stays beside the robot's reading
    positions, _ = command_points(ref, 0.0, np.array([0.0, 3 * np.pi]), ExecutorConfig(), limits)
    np.testing.assert_allclose(positions[:, 1], [3.13 + 2 * np.pi, 3.14 + 2 * np.pi])


def test_a_hold_is_where_the_arm_is_now_within_the_limits_and_the_velocity_scale() -> None:
    """Reported 0.1 s ago moving at 1 rad/s: the arm is about 0.1 further by now; holding at the report would pull
    it back."""
    positions, times = hold_point(Measured(np.array([0.0, 2.95]), np.array([1.0, 1.0]), 0.1), LIMITS, 0.5)
    np.testing.assert_allclose(positions, [[0.1, 3.0]])  # j1 kept within its limit
    assert times.tolist() == [pytest.approx(0.1 / (1.0 * 0.5))]  # the slowest joint at half its limit
    assert hold_point(Measured(np.zeros(2), np.zeros(2)), LIMITS, 0.5)[1].tolist() == [MIN_SEGMENT_S]


class LaggingRobot(FakeRobot):
    """Its reports are ``age`` seconds old, as a real robot's over a network: the arm has moved on since."""

    def measure(self, t: float) -> Measured:
        self.arm.advance(t)
        return Measured(self.arm.position(t - self.age), self.arm.qd.copy(), self.age)


def test_a_new_plan_is_timed_from_where_the_arm_is_not_from_its_last_report() -> None:
    """The first segment was timed from the report: the arm, 0.1 rad further on, covered 0.15 rad in 0.1 s (1.5 rad/s
    against a limit of 1; on the simulated PR2 4-7 rad/s against 2.3-3.6)."""
    robot = LaggingRobot(np.zeros(2))
    arm = Ros2Arm(LIMITS, np.zeros(2), ExecutorConfig(stale_limit_s=5.0), robot)
    robot.age = 0.1
    arm.adopt(make_plan(np.zeros(2), [np.array([1.0, 0.0])], t=11, dt=0.1, names=NAMES))  # j0 at its 1 rad/s
    for _ in range(5):
        arm.note_occupancy()
        arm.step(0.1)
    here = robot.arm.position(robot.arm.t)
    assert here[0] == pytest.approx(0.5) and arm.q[0] == pytest.approx(0.4)  # the report is 0.1 rad behind
    back = make_plan(arm.q, [np.zeros(2)], t=9, dt=0.1, names=NAMES, tick=1)  # turn back, 0.05 rad per 0.1 s
    arm.adopt(back)
    arm.note_occupancy()
    arm.step(0.1)
    positions, times = robot.sent[-1]
    speed = np.abs(np.diff(np.vstack([here, positions]), axis=0)) / np.diff(np.concatenate([[0.0], times]))[:, None]
    assert speed.max() <= LIMITS.velocity.max() * ExecutorConfig().velocity_scale + 1e-9
    assert np.all(speed <= LIMITS.velocity + 1e-9)


def test_the_present_configuration_counts_the_time_since_the_report_was_read() -> None:
    """Real time: the report was read at the end of the last step, h before the command (its age then: age_s)."""
    report = Measured(np.array([0.0, 2.9]), np.array([1.0, 1.0]), 0.05)
    np.testing.assert_allclose(present(report, LIMITS), [0.05, 2.95])
    np.testing.assert_allclose(present(report, LIMITS, since_s=0.02), [0.07, 2.97])
    np.testing.assert_allclose(present(report, LIMITS, since_s=0.5), [0.55, 3.0])  # j1 within its limit


def test_a_continuous_joint_reported_unwrapped_is_wrapped_and_commanded_the_short_way() -> None:
    """A wrist at 0.1 rad reported as 2 pi + 0.1 (as ros2_control reports a continuous joint) was clamped to pi."""
    limits = ArmLimits(NAMES, np.array([-3.0, -np.pi]), np.array([3.0, np.pi]), np.array([1.0, 2.0]),
                       continuous=("j1",))
    q0 = np.array([0.0, 2 * np.pi + 0.1])
    robot = FakeRobot(q0)
    arm = Ros2Arm(limits, q0, ExecutorConfig(stale_limit_s=5.0), robot)
    np.testing.assert_allclose(arm.q, [0.0, 0.1])  # the planner's value of the same angle
    arm.adopt(make_plan(arm.q, [np.array([0.2, 0.5])], t=11, dt=0.1, names=NAMES))
    arm.note_occupancy()
    arm.step(0.1)
    positions, _ = robot.sent[0]
    np.testing.assert_allclose(positions[-1], [0.2, 2 * np.pi + 0.5])  # on from the robot's own reading
    assert np.all(np.abs(np.diff(positions[:, 1])) < 1.0)  # never round through the wrap
    np.testing.assert_allclose(arm.q[1], 0.1 + (0.5 - 0.1) * 0.1, atol=1e-6)  # measured, wrapped back
    with pytest.raises(Exception, match="continuous"):
        ArmLimits(NAMES, limits.lower, limits.upper, limits.velocity, continuous=("j7",))


def test_the_separation_guard_is_asked_before_the_robot_is_commanded() -> None:
    """A ROS 2 robot runs the trajectory it was sent on its own: the guard refusing a step in the core's simulated
    bookkeeping held nothing (the state said 'holding', the robot went on). The arm asks it first and sends a hold."""
    arm, robot = _arm(ExecutorConfig(mode="realtime", stale_limit_s=5.0))
    asked: list[tuple[np.ndarray, np.ndarray]] = []
    near = [True]

    def guard(q: np.ndarray, q_next: np.ndarray) -> str:  # the person stands beyond j0 = 0.3
        asked.append((q.copy(), q_next.copy()))
        return "the person is near" if near[0] and q_next[0] > 0.3 and q_next[0] > q[0] else ""

    arm.guard = guard
    arm.adopt(make_plan(np.zeros(2), [np.array([0.5, 1.0])], t=11, dt=0.1, names=NAMES))
    for _ in range(8):
        arm.note_occupancy()
        arm.step(0.1)
    assert arm.holding and arm.reason == "the person is near" and arm.sent_holds == 1
    assert 0.25 <= arm.q[0] <= 0.35  # the robot itself stopped, a step's travel at most past the line
    np.testing.assert_allclose(asked[-1][0], arm.q)  # asked with where the robot is, measured
    held = arm.q.copy()
    arm.note_occupancy()
    arm.step(0.1)
    np.testing.assert_allclose(arm.q, held)
    near[0] = False  # the person steps back: the plan is sent again, from where the robot is
    for _ in range(12):
        arm.note_occupancy()
        arm.step(0.1)
    assert arm.reached and not arm.holding and arm.sent_plans == 2
