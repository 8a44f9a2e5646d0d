"""The executor's line to a ROS 2 robot over rmw_zenoh (``robot = "ros2"``): commands out, joint states in.

A node ``foresight_executor`` on the executor's session publishes each command
(:class:`services.ros2.arm.Ros2Arm`) as ``trajectory_msgs/JointTrajectory`` on
``/<ros2_controller>/joint_trajectory`` and, in lock-step, the simulated time on ``/clock``
(``rosgraph_msgs/Clock``, what a simulated robot with ``use_sim_time`` follows); it subscribes to the
robot's ``sensor_msgs/JointState`` on ``ros2_joint_states``, each sample checked (type hash,
attachment, the arm's joints present, finite values: one logged line and the sample dropped).

Lock-step: :meth:`Ros2RobotLink.measure` puts ``/clock`` = t and waits (at most ``lockstep_timeout_s``)
for the joint state the robot stamps t, so a run does not depend on timing. Real time: the newest state
and how long ago it arrived; the arm holds the robot when that is older than ``stale_limit_s``.
Every command sent and every joint state received is also written to the run's MCAP as the ROS 2
message it is (``cdr``, schema ``ros2msg``), under its ROS 2 topic name.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from services.executor.config import ExecutorConfig, ExecutorError
from shared.rejects import RejectCounter

from .arm import Measured
from .core import CLOCK_TOPIC, ROBOT_TYPES, Ros2Config, Ros2InputError, Ros2Mapping, command_topic
from .node import Ros2Node

__all__ = ["Ros2RobotLink", "NODE_NAME", "Ros2Log"]

log = logging.getLogger("foresight.executor")

NODE_NAME = "foresight_executor"
"""The executor's ROS 2 node name when it drives a ROS 2 robot."""

STAMP_TOLERANCE_S = 1e-6
"""A lock-step joint state answers ``/clock`` = t when its stamp is within this of t (Time has ns resolution)."""

Ros2Log = Callable[[str, str, bytes], None]
"""``(topic, msgtype, cdr)``: where the link writes what it sends and receives (the MCAP), or nothing."""


class Ros2RobotLink:
    """Commands to, and joint states from, a ROS 2 robot (a :class:`services.ros2.arm.RobotLink`).

    Args:
        session: The executor's open Zenoh session (connected to the robot's rmw_zenoh router).
        config: ``ros2_controller``, ``ros2_joint_states``, ``ros2_domain_id``, ``mode``, ``lockstep_timeout_s``.
        joint_names: The arm's joints, in the order of ``q``.
        stop: Set when the run ends (a wait for the robot gives up).
        rejects: Where refused joint states are counted.
        record: Called with each ROS 2 message sent or received (for the log), or None.
    """

    def __init__(self, session: Any, config: ExecutorConfig, joint_names: list[str], stop: threading.Event,
                 rejects: RejectCounter, record: Ros2Log | None = None) -> None:
        self.config = config
        self.joint_names = list(joint_names)
        self.stop = stop
        self.record = record or (lambda topic, msgtype, data: None)
        self.lockstep = config.mode == "lockstep"
        self.mapping = Ros2Mapping(Ros2Config(domain_id=config.ros2_domain_id))
        self.command_topic = command_topic(config.ros2_controller)
        self.node = Ros2Node(session, config.ros2_domain_id, "/", NODE_NAME, self.mapping.hashes, rejects)
        self._command = self.node.publisher(self.command_topic, ROBOT_TYPES["command"])
        self._clock = self.node.publisher(CLOCK_TOPIC, ROBOT_TYPES["clock"]) if self.lockstep else None
        self._cond = threading.Condition()
        self._latest: tuple[float, np.ndarray, np.ndarray, float] | None = None  # stamp, q, qd, arrival
        self.received = 0
        self.node.subscription(config.ros2_joint_states, ROBOT_TYPES["state"], self._on_state)

    def _on_state(self, payload: bytes) -> None:
        state = self.mapping.joint_state_in(payload, self.joint_names)  # Ros2InputError: refused, counted
        try:
            if state is None:  # another driver's joints (a gripper's) on the same topic
                return
            stamp, q, qd = state
            with self._cond:
                if self._latest is not None and stamp < self._latest[0]:
                    raise Ros2InputError(f"JointState: stamped {stamp:.3f} s, older than the last one "
                                         f"({self._latest[0]:.3f} s): two publishers on "
                                         f"{self.config.ros2_joint_states}?")
                self._latest = (stamp, q, qd, time.monotonic())
                self.received += 1
                self._cond.notify_all()
        finally:  # logged after the state is taken: a recorder that fails cannot cost the arm its state
            self.record(self.config.ros2_joint_states, ROBOT_TYPES["state"], payload)

    def _wait(self, ready: Callable[[], bool], timeout: float, poke: Callable[[], None] | None = None) -> bool:
        end = time.monotonic() + timeout
        with self._cond:
            while not ready():
                if self.stop.is_set() or time.monotonic() >= end:
                    return False
                if poke is not None:
                    poke()
                self._cond.wait(0.2)
        return True

    def initial(self, timeout: float) -> np.ndarray:
        """``(D,)`` the robot's configuration before the run (lock-step: its answer to ``/clock`` = 0).

        Raises:
            ExecutorError: No valid joint state within ``timeout`` seconds.
        """
        poke = (lambda: self._put_clock(0.0)) if self.lockstep else None  # until the robot has subscribed
        if not self._wait(lambda: self._latest is not None, timeout, poke):
            if self.stop.is_set():
                raise ExecutorError("robot: stopped while waiting for its first joint state")
            raise ExecutorError(f"robot: no valid sensor_msgs/JointState with joints {self.joint_names} on "
                                f"{self.config.ros2_joint_states} (domain {self.config.ros2_domain_id}) within "
                                f"{timeout:.0f} s")
        assert self._latest is not None
        if self.lockstep and abs(self._latest[0]) > STAMP_TOLERANCE_S:
            raise ExecutorError(f"robot: its joint state answering /clock = 0 is stamped {self._latest[0]:.3f} s: it "
                                "does not follow /clock (a lock-step run needs a simulated robot with use_sim_time, "
                                "e.g. foresight simrobot --sim-time; a real robot runs in real time)")
        log.info("executor: ROS 2 robot found: %s, commands to %s", self.config.ros2_joint_states,
                 self.command_topic)
        return self._latest[1].copy()

    def _put_clock(self, t: float) -> None:
        assert self._clock is not None
        data = self.mapping.clock(t)
        self._clock.put(data)
        self.record(CLOCK_TOPIC, ROBOT_TYPES["clock"], data)

    def send(self, positions: np.ndarray, times: np.ndarray) -> None:
        """Send one ``JointTrajectory`` to the controller."""
        data = self.mapping.command(self.joint_names, positions, times)
        self._command.put(data)
        self.record(self.command_topic, ROBOT_TYPES["command"], data)

    def measure(self, t: float) -> Measured:
        """The robot's state at the executor's time ``t``.

        Raises:
            ExecutorError: Lock-step, and the robot did not answer ``/clock`` = t within ``lockstep_timeout_s``
                (unless the run is stopping).
        """
        if self.lockstep:
            self._put_clock(t)
            if not self._wait(lambda: self._latest is not None and abs(self._latest[0] - t) <= STAMP_TOLERANCE_S,
                              self.config.lockstep_timeout_s):
                if not self.stop.is_set():  # stopping: the last state known will do
                    raise ExecutorError(f"robot: no joint state stamped {t:.3f} s (sim time, /clock) within "
                                    f"{self.config.lockstep_timeout_s:.0f} s")
        with self._cond:
            assert self._latest is not None
            _, q, qd, arrival = self._latest
            return Measured(q.copy(), qd.copy(), 0.0 if self.lockstep else time.monotonic() - arrival)

    def close(self) -> None:
        """Undeclare the node."""
        self.node.close()
