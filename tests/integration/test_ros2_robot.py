"""A ROS 2 robot driven through a whole lock-step run (issue 26): the executor with ``robot = "ros2"``, the test robot
(:mod:`services.ros2.robot_sim`) speaking rmw_zenoh on the same Zenoh network, following ``/clock``."""

from __future__ import annotations

import dataclasses

import numpy as np
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from services.experiments.harness import ServiceThread
from services.ros2.robot_sim import RobotSim, RobotSimConfig

TS = get_typestore(Stores.ROS2_JAZZY)


def _ros2_channels(path: str) -> dict[str, list[object]]:
    out: dict[str, list[object]] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.message_encoding == "cdr":
                assert schema is not None and schema.encoding == "ros2msg"
                out.setdefault(channel.topic, []).append(TS.deserialize_cdr(message.data, schema.name))
    return out


def _run(run_system, steps: int):
    system = run_system(mode="lockstep", steps=steps, executor_overrides={"robot": "ros2"})
    robot_zenoh = dataclasses.replace(system.hub, listen=["tcp/127.0.0.1:0"], connect=list(system.hub.listen),
                                      role="")
    robot = RobotSim(RobotSimConfig(), robot_zenoh)
    thread = ServiceThread("simrobot", robot.run)
    thread.start()
    try:
        result = system.executor_result()
    finally:
        thread.stop_event.set()
        thread.join(20.0)
    return system, robot, result


def test_a_ros2_robot_is_driven_through_a_lockstep_run_the_same_every_time(run_system):
    steps = 8
    system, robot, result = _run(run_system, steps)
    plans, states, _, _ = system.recorder.snapshot()
    assert result.steps == steps and sorted({p.tick for p in plans}) == list(range(steps))
    arm = system.services["executor"].core
    assert type(arm).__name__ == "Ros2Arm" and arm.sent_plans >= 1
    assert robot.arm.received == arm.sent_plans + arm.sent_holds, "every command reached the robot"
    assert robot.rejects.total == 0 and system.services["executor"].rejects.total == 0
    # the states the planner planned from are the robot's: the last one is where the robot is
    last = max(states, key=lambda s: s.stamp)
    np.testing.assert_allclose(last.q, robot.arm.q, atol=1e-12)
    assert not last.holding and last.goal == plans[-1].chosen
    # the robot moved along the commanded trajectories, and the log has the ROS 2 side as it went
    assert np.max(np.abs(result.q[-1] - result.q[0])) > 0.05
    ros = _ros2_channels(result.mcap_path)
    commands = ros["/r_arm_controller/joint_trajectory"]
    assert len(commands) == robot.arm.received and len(commands[0].points) >= 1
    substeps = system.services["executor"].config.substeps
    assert len(ros["/clock"]) >= steps * substeps  # and /clock = 0 until the robot answered
    assert len(ros["/joint_states"]) >= steps * substeps + 1
    # lock-step: the same robot motion on every run (the robot's commands and clock are handled in order)
    _, _, again = _run(run_system, steps)
    np.testing.assert_array_equal(again.q, result.q)
    assert again.goal_per_step == result.goal_per_step
