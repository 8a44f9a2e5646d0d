"""The executor's options (``[executor]``): the run, the simulated arm's pace, the safety hold, the log, the robot."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from services.ros2.domain import UNREADABLE_DOMAIN, check_domain_id, ros_domain_id
from services.ros2.wire import ROS_NAME, topic_problem
from shared.atomic_file import make_parent
from shared.config import LOG_LEVELS, ConfigError, nested, opt
from shared.config_names import check_services
from shared.devices import check_device
from shared.protocol import HUMAN_SOURCES, SERVICES
from shared.protocol.limits import MAX_PERIOD_S, MIN_PERIOD_S
from shared.scene import SCENE_HELP

__all__ = ["ExecutorConfig", "ExecutorError", "SeparationConfig", "SEPARATION_REASON", "is_separation_hold", "ROBOTS",
           "lockstep_stale_limit", "check_robot_names"]

ROBOTS = ("sim", "ros2")
"""What the executor drives: its own simulated arm, or a ROS 2 robot's joint_trajectory_controller."""


def check_robot_names(controller: str, joint_states: str, prefix: str) -> None:
    """Refuse a ROS 2 robot's controller name or joint-state topic that ROS 2 cannot have.

    Raises:
        ConfigError: Named ``<prefix>controller`` or ``<prefix>joint_states`` (e.g. ``executor.ros2_controller``).
    """
    if not ROS_NAME.fullmatch(controller):
        raise ConfigError(f"{prefix}controller: a controller name of letters, digits and '_', not starting with a "
                          f"digit (ROS 2's rule for a name; no '/'), got {controller!r}")
    problem = topic_problem(joint_states)
    if problem:
        raise ConfigError(f"{prefix}joint_states: {problem}")


class ExecutorError(ValueError):
    """A plan or configuration the executor cannot use; the message names what is wrong."""


SEPARATION_REASON = ("the person is {clearance:.2f} m from the robot (separation stop_m {stop_m:.2f} m): no move "
                     "closer; it moves again when its next step keeps its distance")
"""The hold reason of the separation guard (``RobotState.reason``)."""


def lockstep_stale_limit(period_s: float, limit_s: float = 0.0) -> float:
    """The stale limit a lock-step run of ``period_s`` needs: ``limit_s``, or 1.5 periods when the period exceeds it.

    A plan of tick n-1 is a period old when step n adopts it: a limit below the period held every step. 1.5 periods
    makes a plan stale once one is missing, as the default 0.5 s does at the default 0.5 s period.
    """
    return 1.5 * period_s if period_s > limit_s else limit_s


def is_separation_hold(reason: str) -> bool:
    """Whether a ``RobotState.reason`` is the separation guard's (:data:`SEPARATION_REASON`)."""
    head, _, rest = SEPARATION_REASON.partition("{clearance:.2f}")
    return reason.startswith(head) and rest.split("{")[0] in reason


@dataclass
class SeparationConfig:
    """The separation guard's options (``[executor.separation]``; :mod:`services.executor.separation`)."""

    stop_m: float = opt(0.05, help="real time: a robot nearer the person's body than this (m, its collision spheres to "
                        "the body's capsules) makes no move that brings it closer; it holds until a move keeps or "
                        "widens the gap (0.05: the posed body's error under a depth camera's noise, about 4 cm at the "
                        "hand; docs/executor.md); 0: off")
    window_s: float = opt(0.5, help="the person is where any of their poses of the last window_s puts them (the "
                          "nearest counts: a noisy pose that shows them further away lets the robot no nearer; s)")

    def validate(self) -> None:
        """Raise :class:`ConfigError` naming a bad value."""
        if not (self.stop_m >= 0 and math.isfinite(self.stop_m)):
            raise ConfigError(f"executor.separation.stop_m: must be a finite number >= 0 (0: off), got {self.stop_m}")
        if not (self.window_s >= 0 and math.isfinite(self.window_s)):
            raise ConfigError(f"executor.separation.window_s: must be a finite number >= 0 s, got {self.window_s}")


@dataclass
class ExecutorConfig:
    """Executor options (``[executor]`` in a config file, ``FORESIGHT_EXECUTOR_<NAME>`` in the environment)."""

    mode: str = opt("lockstep", help="lockstep: the executor is the simulation master and emits clock ticks; "
                    "realtime: wall clock", choices=("lockstep", "realtime"))
    steps: int = opt(20, help="replanning steps to run (the paper runs 20); 0 = until stopped")
    step_period_s: float = opt(0.2, help="replanning period: simulated seconds per clock tick (lockstep) or the "
                               "run length unit steps * period (realtime)")
    state_rate_hz: float = opt(50.0, help="RobotState publishing rate (per simulated second in lockstep, rounded to "
                               "a whole number of states per step, at least 1)")
    stale_limit_s: float = opt(0.5, help="hold the robot when the latest plan or occupancy is older than this")
    require_occupancy: bool = opt(True, help="also hold when the occupancy prediction is missing or stale")
    hold_without: list[str] = opt(default_factory=lambda: ["predictor", "planner", "replayer", "tracker"],
                                  help="hold while one of these services, once seen, is gone (its liveliness "
                                  "token lost: stopped or killed), before its inputs are stale; a human's source of "
                                  "recorded_sources only when it goes in the middle of a demonstration or reach; "
                                  "empty = never")
    recorded_sources: list[str] = opt(default_factory=lambda: ["replayer"],
                                      help="the human's sources that play a recording: one that goes after a "
                                      "demonstration's end ended its stream (the person stands as last seen); the "
                                      "others (a live tracker) going means nobody watches the person, and holds the "
                                      "robot (foresight demo --human keypoints adds its tracker, which plays a file)")
    goal_tolerance: float = opt(0.02, help="goal reached when every joint is within this of the goal (rad or m)")
    velocity_scale: float = opt(1.0, help="fraction of the robot's joint velocity limits the simulation may use")
    stop_on_goal: bool = opt(False, help="end the run at the end of the step in which the goal is reached")
    path_per_step: float = opt(0.0, help="advance this configuration-space length (weighted joint-space Euclidean "
                               "norm) along the chosen trajectory per step_period_s, whatever the plan's timing, "
                               "within the velocity limits (the paper authors' pace, docs/experiments.md); 0: follow "
                               "the plan in time")
    path_weights: list[float] = opt(default_factory=list, help="per-joint weights of the configuration-space length "
                                    "of path_per_step (Move3D weighs a revolute joint by the size of its body; "
                                    "empty: 1 each)")
    finish_path: bool = opt(False, help="lockstep: after the last step, execute the rest of the last plan without "
                            "replanning, at the same pace (the paper authors' protocol)")
    finish_s: float = opt(0.0, help="realtime: after the run's steps x step_period_s, go on (adopting plans as "
                          "before) until the robot reaches its goal, at most this many seconds more (lock-step's "
                          "finish_path in real time; 0: the run ends at its length)")
    lockstep_timeout_s: float = opt(30.0, help="lockstep: longest wait (wall s) for the plan of a tick before "
                                    "going on without it")
    wait_for: list[str] = opt(default_factory=lambda: ["replayer", "predictor", "planner"],
                              help="services whose liveliness token to wait for (at most startup_timeout_s) "
                              "before the run starts: the first tick (lockstep) or the clock (realtime)")
    startup_timeout_s: float = opt(300.0, help="longest wait (wall s) for the wait_for services")
    start_q: list[float] = opt(default_factory=list, help="start configuration, one value per joint in the "
                               "robot model's order (empty: the robot model's start configuration)")
    scene: str = opt("", help=SCENE_HELP + " (empty: pr2_two_cups)")
    mcap: str = opt("", help="MCAP log path (empty: runs/<UTC timestamp>.mcap; 'none': no log)")
    mcap_compression: str = opt("zstd", choices=("zstd", "lz4", "none"),
                                help="compression of the MCAP's chunks (every MCAP reader reads zstd and lz4)")
    viz_rate_hz: float = opt(5.0, help="highest rate of the Foxglove robot/human/occupancy scene updates per channel")
    live_port: int = opt(0, help="also serve the logged scene live to the Foxglove app on ws://LIVE_HOST:PORT "
                         "(foxglove-sdk; docs/live-view.md); 0: off")
    live_host: str = opt("127.0.0.1", help="the live server's address (loopback: only this machine can watch)")
    device: str = opt("cpu", help="torch device of the robot model (cpu or cuda)")
    robot: str = opt("sim", choices=ROBOTS, help="sim: simulate the arm; ros2: drive a ROS 2 robot over rmw_zenoh "
                     "(its JointState in, each plan out to its joint_trajectory_controller, the same holds; lock-step "
                     "runs publish /clock; docs/ros2.md)")
    ros2_controller: str = opt("r_arm_controller", help="robot=ros2: the controller; plans go to "
                               "/<controller>/joint_trajectory (trajectory_msgs/JointTrajectory)")
    ros2_joint_states: str = opt("/joint_states", help="robot=ros2: the robot's sensor_msgs/JointState topic")
    ros2_domain_id: int = opt(default_factory=lambda: ros_domain_id(), help="robot=ros2: the ROS 2 domain id "
                              "(default: $ROS_DOMAIN_ID, else 0)")
    log_level: str = opt("INFO", help="log level", choices=LOG_LEVELS)
    separation: SeparationConfig = nested(SeparationConfig, help="real time: the separation guard (no move closer to "
                                          "the person once within stop_m; docs/executor.md)")

    def validate(self) -> None:
        """Check ranges; raises ConfigError naming the option."""
        self.separation.validate()
        positive = ("step_period_s", "state_rate_hz", "stale_limit_s", "goal_tolerance", "velocity_scale",
                    "lockstep_timeout_s", "startup_timeout_s", "viz_rate_hz")
        for name in positive:
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ConfigError(f"executor.{name}: must be > 0, got {value}")
        if not MIN_PERIOD_S <= self.step_period_s <= MAX_PERIOD_S:  # the clock tick's period on the wire
            raise ConfigError(f"executor.step_period_s: must be in [{MIN_PERIOD_S:g}, {MAX_PERIOD_S:g}] s (a clock "
                              f"tick's period, docs/protocol.md), got {self.step_period_s}")
        if self.steps < 0:
            raise ConfigError(f"executor.steps: must be >= 0, got {self.steps}")
        if self.mode == "lockstep" and self.stale_limit_s < self.step_period_s:
            # a plan of tick n-1 is adopted at step n, a period old: every step held, the robot never moved
            raise ConfigError(f"executor.stale_limit_s: {self.stale_limit_s:g} s is below the lock-step period "
                              f"{self.step_period_s:g} s: every plan is a period old when adopted and the robot would "
                              f"hold at every step; give at least {lockstep_stale_limit(self.step_period_s):g} "
                              "(1.5 periods: stale once a plan is missing)")
        if self.velocity_scale > 1.0:
            raise ConfigError(f"executor.velocity_scale: must be <= 1, got {self.velocity_scale}")
        if not (self.finish_s >= 0 and math.isfinite(self.finish_s)):
            raise ConfigError(f"executor.finish_s: must be >= 0 s, got {self.finish_s}")
        if not (self.path_per_step >= 0 and math.isfinite(self.path_per_step)):
            raise ConfigError(f"executor.path_per_step: must be >= 0, got {self.path_per_step}")
        if not all(w > 0 and math.isfinite(w) for w in self.path_weights):
            raise ConfigError(f"executor.path_weights: must be finite and > 0, got {self.path_weights}")
        for name in ("wait_for", "hold_without"):
            check_services(getattr(self, name), f"executor.{name}", [s for s in SERVICES if s != "executor"])
        check_services(self.recorded_sources, "executor.recorded_sources", list(HUMAN_SOURCES))
        if self.robot == "ros2" or self.ros2_domain_id != UNREADABLE_DOMAIN:  # the shell's ROS_DOMAIN_ID: if used
            check_domain_id(self.ros2_domain_id, "executor.ros2_domain_id", "--ros2-domain-id")
        check_robot_names(self.ros2_controller, self.ros2_joint_states, "executor.ros2_")
        if not 0 <= self.live_port <= 65535:
            raise ConfigError(f"executor.live_port: must be a port 1..65535 (0: off), got {self.live_port}")
        if self.live_port and self.mcap.lower() == "none":
            raise ConfigError("executor.live_port: the live scene is the log's; it needs the MCAP log (mcap is 'none')")
        if not all(math.isfinite(v) for v in self.start_q):
            raise ConfigError(f"executor.start_q: values must be finite, got {self.start_q}")
        check_device(self.device, "executor.device")

    @property
    def substeps(self) -> int:
        """Simulation substeps per replanning period (one RobotState each)."""
        return max(1, round(self.step_period_s * self.state_rate_hz))

    def state_rate_note(self) -> str:
        """In lock-step, the rate :attr:`substeps` gives where it is not ``state_rate_hz`` (a line to log at start).

        A step publishes a whole number of states, at least one: 1, 2.6 and 7 Hz all published at 5 Hz with 0.2 s
        steps, without a word. "" in real time, or where the rate is kept.
        """
        used = self.substeps / self.step_period_s
        if self.mode != "lockstep" or math.isclose(used, self.state_rate_hz, rel_tol=1e-9):
            return ""
        return (f"executor: lock-step publishes {self.substeps} RobotState(s) per {self.step_period_s:g} s step, "
                f"{used:g} Hz of simulated time, not state_rate_hz {self.state_rate_hz:g} (a whole number per step, "
                "at least 1)")

    def mcap_path(self, now: str) -> Path | None:
        """The MCAP path to write (``now``: a UTC timestamp for the default name), or None for 'none'.

        The default name is claimed: created, empty, only if no file has it (``O_EXCL``), else ``-2``, ``-3``... A
        check for the name followed by the open let two executors started within the same second both take it, and
        the second was refused by the first one's lock instead of taking ``-2``.

        Raises:
            OSError: ``runs`` cannot be made or written (named).
        """
        if self.mcap.lower() == "none":
            return None
        if self.mcap:
            return Path(self.mcap)
        n = 1
        while True:
            path = make_parent(Path("runs") / (f"{now}.mcap" if n == 1 else f"{now}-{n}.mcap"))
            try:
                os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
                return path
            except FileExistsError:  # a run started within the same second: its log is kept
                n += 1
