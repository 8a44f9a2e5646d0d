"""``foresight simrobot``: a simulated ROS 2 robot speaking rmw_zenoh, to drive with ``--robot ros2``.

The ROS 2 side of a real robot reduced to what Foresight uses: a node ``pr2_sim`` with a
``joint_trajectory_controller`` (:class:`services.ros2.controller.SimulatedController`) subscribed to
``/<controller>/joint_trajectory`` and publishing ``sensor_msgs/JointState`` on ``/joint_states``,
every sample with rmw_zenoh's attachment and every endpoint with its graph token. With ``sim_time`` it
follows ``/clock`` as a ROS 2 node with ``use_sim_time`` does (one joint state, stamped with the clock,
per clock message: what a lock-step run needs); otherwise it runs on the wall clock at ``rate_hz``.
Incoming samples are checked like every receipt (type hash, attachment, joints, NaN, times): one logged
line, the sample dropped, the node running.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any

from services.executor.config import ExecutorConfig, check_robot_names
from services.executor.core import ArmLimits
from services.executor.models import load_models, start_configuration
from shared.config import LOG_LEVELS, ConfigError, ZenohConfig, opt
from shared.config_names import check_services
from shared.protocol import SERVICES, Keys
from shared.rejects import RejectCounter
from shared.scene import SCENE_HELP, load_scene
from shared.transport import Presence, open_session

from .controller import SimulatedController
from .core import CLOCK_TOPIC, ROBOT_TYPES, Ros2Config, Ros2Mapping, check_node_name, command_topic
from .domain import check_domain_id, ros_domain_id
from .node import Ros2Node

__all__ = ["RobotSimConfig", "RobotSim"]

log = logging.getLogger("foresight.simrobot")


@dataclass
class RobotSimConfig:
    """Options of ``foresight simrobot`` (``[simrobot]``)."""

    domain_id: int = opt(default_factory=lambda: ros_domain_id(), help="ROS 2 domain id (default: $ROS_DOMAIN_ID, "
                         "else 0)")
    node: str = opt("pr2_sim", help="ROS 2 node name")
    controller: str = opt("r_arm_controller", help="the controller: commands on /<controller>/joint_trajectory")
    joint_states: str = opt("/joint_states", help="where the joint states go")
    sim_time: bool = opt(True, help="follow /clock (use_sim_time; a lock-step run publishes it); off: wall clock")
    rate_hz: float = opt(100.0, help="joint states per second on the wall clock (sim_time off)")
    scene: str = opt("", help=SCENE_HELP + " (the start configuration, as the executor's; empty: pr2_two_cups)")
    start_q: list[float] = opt(default_factory=list, help="start configuration (empty: the executor's default)")
    stop_with: list[str] = opt(default_factory=list, help="stop when one of these Foresight services (e.g. executor) "
                               "disappears after it was seen (comma-separated, as the other services')")
    log_level: str = opt("INFO", choices=LOG_LEVELS, help="log level")

    def validate(self) -> None:
        """Check ranges and names."""
        check_domain_id(self.domain_id, "simrobot.domain_id", "--domain-id")
        check_node_name(self.node, "simrobot.node")
        if not self.rate_hz > 0:
            raise ConfigError(f"simrobot.rate_hz: must be > 0, got {self.rate_hz}")
        # misspelt, a service is never seen go, and the robot runs on without a word
        check_services(self.stop_with, "simrobot.stop_with", SERVICES)
        check_robot_names(self.controller, self.joint_states, "simrobot.")


class RobotSim:
    """The simulated robot node.

    Args:
        config: Its options.
        zenoh: The session's config (the same Zenoh network as the executor).
    """

    def __init__(self, config: RobotSimConfig, zenoh: ZenohConfig) -> None:
        config.validate()
        self.config = config
        self.zenoh = zenoh
        scene = load_scene(config.scene or None)
        robot, _, _ = load_models(scene, "cpu")
        limits = ArmLimits.from_robot(robot)
        self.joint_names = list(limits.joint_names)
        q0 = start_configuration(limits, ExecutorConfig(start_q=list(config.start_q)), robot, scene)
        self.arm = SimulatedController(q0)
        self.mapping = Ros2Mapping(Ros2Config(domain_id=config.domain_id))
        self.rejects = RejectCounter("simrobot")
        self.published = 0
        self._lock = threading.Lock()
        self._t0 = time.monotonic()
        self._pub: Any = None

    def _now(self) -> float:
        return self.arm.t if self.config.sim_time else time.monotonic() - self._t0

    def _publish(self, stamp: float) -> None:
        self._pub.put(self.mapping.joint_state_of(self.joint_names, self.arm.q, self.arm.qd, stamp))
        self.published += 1

    def on_command(self, payload: bytes) -> None:
        """A ``JointTrajectory``: replaces the one in progress from now."""
        columns, positions, times = self.mapping.trajectory_in(payload, self.joint_names)
        with self._lock:
            self.arm.command(self._now(), columns, positions, times)

    def on_clock(self, payload: bytes) -> None:
        """``/clock``: move to that time and report the state there (a clock going back starts over from here)."""
        t = self.mapping.clock_in(payload)
        with self._lock:
            if t < self.arm.t:  # a new run's clock: the arm stays where it is, its old trajectory dropped
                received = self.arm.received
                self.arm = SimulatedController(self.arm.q)
                self.arm.t, self.arm.received = t, received
            self.arm.advance(t)
            self._publish(t)

    def run(self, stop: threading.Event | None = None) -> int:
        """Serve until ``stop`` is set; returns the number of joint states published."""
        stop = stop or threading.Event()
        cfg = self.config
        with open_session(self.zenoh, stop, "simrobot") as session:
            node = Ros2Node(session, cfg.domain_id, "/", cfg.node, self.mapping.hashes, self.rejects, ordered=True)
            self._pub = node.publisher(cfg.joint_states, ROBOT_TYPES["state"])
            node.subscription(command_topic(cfg.controller), ROBOT_TYPES["command"], self.on_command)
            if cfg.sim_time:
                node.subscription(CLOCK_TOPIC, ROBOT_TYPES["clock"], self.on_clock)
            presence = Presence(session, Keys(self.zenoh.prefix), "simrobot", stop_with=cfg.stop_with, stop=stop)
            log.info("simrobot: node /%s on domain %d: %s in, %s out, %s", cfg.node, cfg.domain_id,
                     command_topic(cfg.controller), cfg.joint_states,
                     "following /clock" if cfg.sim_time else f"{cfg.rate_hz:g} Hz on the wall clock")
            try:
                self._t0 = time.monotonic()
                while not stop.wait(1.0 / cfg.rate_hz if not cfg.sim_time else 0.5):
                    if not cfg.sim_time:
                        with self._lock:
                            self.arm.advance(self._now())
                            self._publish(time.time())
            finally:
                presence.close()
                node.close()
        log.info("simrobot: stopped; %d trajectories received, %d joint states sent, %d samples refused (%s)",
                 self.arm.received, self.published, self.rejects.total, self.rejects.summary())
        return self.published


DESCRIPTION = """A simulated PR2 arm on ROS 2 over rmw_zenoh, to try `foresight executor --robot ros2` (or
`foresight demo --robot ros2`) without a robot: a node with a joint_trajectory_controller that follows each
trajectory_msgs/JointTrajectory on /<controller>/joint_trajectory exactly, and sensor_msgs/JointState on
/joint_states; with --sim-time (default) it follows /clock as a node with use_sim_time does (lock-step runs).
Options: defaults < --config FILE ([simrobot], [zenoh]) < env FORESIGHT_SIMROBOT_<NAME> < flags."""


def main(argv: list[str] | None = None, prog: str = "python -m services.ros2.robot_sim") -> int:
    """Run the simulated robot; returns the exit status (0 stopped, 2 bad input)."""
    from shared.runtime import service_main
    from shared.security.acl import refuse_ros2_keys

    def make(cfg: RobotSimConfig, zcfg: ZenohConfig, stop: threading.Event) -> Any:
        refuse_ros2_keys(zcfg.security_dir, "foresight simrobot")
        sim = RobotSim(cfg, zcfg)
        return lambda: sim.run(stop)

    return service_main(argv, prog, section="simrobot", config_cls=RobotSimConfig, description=DESCRIPTION,
                        make=make)


if __name__ == "__main__":
    import sys

    sys.exit(main())
