"""The executor's line to a ROS 2 robot, on loopback Zenoh: the simulated robot found and driven in real time, and
what the robot sends refused with its reason (type hash, attachment, joints, NaN) without stopping either side."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from services.executor.config import ExecutorConfig
from services.executor.core import ArmLimits
from services.ros2.arm import hold_point
from services.ros2.core import Ros2Config, Ros2Mapping
from services.ros2.link import Ros2RobotLink
from services.ros2.robot_sim import RobotSim, RobotSimConfig
from services.ros2.wire import Attachment, data_key
from shared.config import ZenohConfig
from shared.rejects import RejectCounter
from shared.robot import JOINT_NAMES
from shared.transport import open_session

STATE = "sensor_msgs/msg/JointState"


def test_the_robot_is_found_driven_and_bad_samples_are_refused(
        zenoh_hub: Callable[[], ZenohConfig], wait_until: Callable[..., bool]) -> None:
    hub = zenoh_hub()
    robot = RobotSim(RobotSimConfig(sim_time=False, rate_hz=50.0), zenoh_hub())
    stop, robot_stop = threading.Event(), threading.Event()
    thread = threading.Thread(target=robot.run, args=(robot_stop,), daemon=True)
    thread.start()
    mapping = Ros2Mapping(Ros2Config())
    names = list(JOINT_NAMES)
    rejects = RejectCounter("executor")
    recorded: list[str] = []
    try:
        with open_session(hub) as session, open_session(zenoh_hub()) as other:
            link = Ros2RobotLink(session, ExecutorConfig(mode="realtime", robot="ros2"), names, stop, rejects,
                                 record=lambda topic, msgtype, data: recorded.append(topic))
            try:
                q0 = link.initial(30.0)
                np.testing.assert_allclose(q0, robot.arm.q)
                target = q0 + 0.1
                link.send(target[None], np.array([0.3]))
                assert wait_until(lambda: np.allclose(link.measure(0.0).q, target, atol=1e-9), 10.0)
                assert 0.0 <= link.measure(0.0).age_s < 5.0  # a fresh reading (a loaded machine may delay it)
                # samples the executor must refuse, each with its reason; then a good one still counts
                key = data_key(0, "/joint_states", STATE, mapping.hashes[STATE])
                att = Attachment(1, time.time_ns(), b"\x01" * 16).encode()
                good = mapping.joint_state_of(names, q0, np.zeros(len(names)), 1.0)
                other.put(data_key(0, "/joint_states", STATE, "RIHS01_" + "0" * 64), good, attachment=att)
                other.put(key, good)  # no attachment
                other.put(key, mapping.joint_state_of(names[:-1], q0[:-1], np.zeros(7), 1.0), attachment=att)
                other.put(key, mapping.joint_state_of(names, q0 * np.nan, np.zeros(len(names)), 1.0),
                          attachment=att)
                other.put(key, b"\x00\x01\x00\x00\x03", attachment=att)
                assert wait_until(lambda: rejects.total >= 5, 10.0)
                reasons = {why for (_, why) in rejects.by_reason}
                assert reasons == {"type", "attachment", "malformed"}
                assert rejects.counts == {"/joint_states": 5}
                before = link.received
                assert wait_until(lambda: link.received > before + 3, 10.0)  # the robot's own states still come
                # a command the robot must refuse (a joint it does not have); it keeps running
                cmd = data_key(0, "/r_arm_controller/joint_trajectory", "trajectory_msgs/msg/JointTrajectory",
                               mapping.hashes["trajectory_msgs/msg/JointTrajectory"])
                other.put(cmd, mapping.command(["no_such_joint"], np.zeros((1, 1)), np.array([1.0])),
                          attachment=att)
                assert wait_until(lambda: robot.rejects.total == 1, 10.0)
                assert robot.rejects.counts == {"/r_arm_controller/joint_trajectory": 1}
                link.send(q0[None], np.array([0.2]))
                assert wait_until(lambda: np.allclose(link.measure(0.0).q, q0, atol=1e-9), 10.0)
                # the hold: a trajectory without points is refused, as ros2_controllers refuses it ("Empty trajectory
                # received.") and the motion goes on; the executor's one point where the arm is stops it
                far = q0 + 0.3
                link.send(far[None], np.array([3.0]))
                time.sleep(0.5)
                link.send(np.zeros((0, len(names))), np.zeros(0))
                assert wait_until(lambda: robot.rejects.total == 2, 10.0)
                moving = link.measure(0.0).q
                time.sleep(0.3)
                assert not np.allclose(link.measure(0.0).q, moving, atol=1e-4)  # still under way: no hold
                limits = ArmLimits(tuple(names), np.full(len(names), -10.0), np.full(len(names), 10.0),
                                   np.ones(len(names)))
                link.send(*hold_point(link.measure(0.0), limits, 0.5))
                time.sleep(0.5)
                held = link.measure(0.0).q
                time.sleep(0.3)
                assert np.allclose(link.measure(0.0).q, held, atol=1e-6) and not np.allclose(held, far, atol=0.05)
            finally:
                link.close()
    finally:
        robot_stop.set()
        thread.join(10.0)
    assert not thread.is_alive()
    assert "/r_arm_controller/joint_trajectory" in recorded and "/joint_states" in recorded
    assert robot.arm.received == 4  # the refused commands never reached the arm


def test_no_robot_is_one_clear_error(zenoh_hub: Callable[[], ZenohConfig]) -> None:
    from services.executor.config import ExecutorError

    with open_session(zenoh_hub()) as session:
        link = Ros2RobotLink(session, ExecutorConfig(mode="realtime", robot="ros2"), list(JOINT_NAMES),
                             threading.Event(), RejectCounter("executor"))
        try:
            with pytest.raises(ExecutorError, match=r"no valid sensor_msgs/JointState .* on /joint_states"):
                link.initial(0.5)
        finally:
            link.close()


def test_a_joint_state_is_taken_even_when_its_recording_fails(zenoh_hub: Callable[[], ZenohConfig]) -> None:
    """The state was recorded before it was taken: a recorder that raised (a log the disk had ended) cost the arm
    every joint state."""
    mapping = Ros2Mapping(Ros2Config())
    names = list(JOINT_NAMES)

    def failing(topic: str, msgtype: str, data: bytes) -> None:
        raise OSError(28, "No space left on device")

    with open_session(zenoh_hub()) as session:
        link = Ros2RobotLink(session, ExecutorConfig(mode="realtime", robot="ros2"), names, threading.Event(),
                             RejectCounter("executor"), record=failing)
        q = np.linspace(0.1, 0.8, len(names))
        with pytest.raises(OSError):
            link._on_state(mapping.joint_state_of(names, q, np.zeros(len(names)), 2.0))
        np.testing.assert_allclose(link.measure(0.0).q, q)
        assert link.received == 1
