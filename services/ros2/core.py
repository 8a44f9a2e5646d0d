"""Foresight messages as ROS 2 messages (pure: no Zenoh; the ``rosbags`` type store encodes them).

:class:`Ros2Mapping` turns each Foresight message into the ROS 2 samples the ``ros2`` service puts on
rmw_zenoh keys (:mod:`services.ros2.wire`), and checks what comes in:

=========================  ==========================================  =========================================
Foresight                  ROS 2 topic (defaults, under ``namespace``)  type
=========================  ==========================================  =========================================
Plan (the chosen goal's)   ``/foresight/joint_trajectory``             ``trajectory_msgs/msg/JointTrajectory``
Plan (the goal's name)     ``/foresight/goal``                         ``std_msgs/msg/String``
RobotState                 ``/joint_states``                           ``sensor_msgs/msg/JointState``
OccupancyGrid              ``/foresight/occupancy``                    ``visualization_msgs/msg/MarkerArray``
HumanPose                  ``/foresight/human``                        ``visualization_msgs/msg/MarkerArray``
ClassPosterior             ``/foresight/posterior``                    ``diagnostic_msgs/msg/KeyValue`` list as
                                                                        ``diagnostic_msgs/msg/DiagnosticStatus``
ClockTick, RobotState      ``/clock`` (lock-step only)                 ``rosgraph_msgs/msg/Clock``
=========================  ==========================================  =========================================

Frames: everything in the scene's frame, ``frame_id`` (default ``world``, as in the MCAP's scene).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from shared.config import LOG_LEVELS, ConfigError, opt
from shared.protocol import ClassPosterior, HumanPose, OccupancyGrid, Plan, RobotState

from .domain import check_domain_id, ros_domain_id
from .wire import ROS_NAME, data_key

__all__ = ["Ros2Config", "Ros2Mapping", "Topic", "TOPICS", "ROBOT_TYPES", "CLOCK_TOPIC", "command_topic",
           "KEYPOINTS_TYPE", "Ros2InputError", "seconds_in", "time_msg", "check_node_name", "namespaced"]

STORE = "ros2_jazzy"
"""The rosbags type store the message definitions and hashes come from (ROS 2 Jazzy)."""


class Ros2InputError(ValueError):
    """A ROS 2 sample Foresight refuses (wrong type, unknown joints, NaN, ...); the text says why."""


@dataclass(frozen=True)
class Topic:
    """One published topic: its name (relative to the namespace unless absolute) and type."""

    name: str
    msgtype: str


TOPICS = {
    "trajectory": Topic("foresight/joint_trajectory", "trajectory_msgs/msg/JointTrajectory"),
    "goal": Topic("foresight/goal", "std_msgs/msg/String"),
    "joint_states": Topic("/joint_states", "sensor_msgs/msg/JointState"),
    "occupancy": Topic("foresight/occupancy", "visualization_msgs/msg/MarkerArray"),
    "human": Topic("foresight/human", "visualization_msgs/msg/MarkerArray"),
    "posterior": Topic("foresight/posterior", "diagnostic_msgs/msg/DiagnosticStatus"),
    "clock": Topic("/clock", "rosgraph_msgs/msg/Clock"),
}
"""What the ``ros2`` service publishes, by role."""

ROBOT_TYPES = {"command": "trajectory_msgs/msg/JointTrajectory", "state": "sensor_msgs/msg/JointState",
               "clock": "rosgraph_msgs/msg/Clock"}
"""What the executor exchanges with a ROS 2 robot (``robot = "ros2"``): plans out, joint states in, /clock out."""

CLOCK_TOPIC = TOPICS["clock"].name
"""The simulated time's topic, the one every ROS 2 node reads with ``use_sim_time``."""


def command_topic(controller: str) -> str:
    """A ``joint_trajectory_controller``'s command topic: ``/<controller>/joint_trajectory``."""
    return f"/{controller}/joint_trajectory"


KEYPOINTS_TYPE = "geometry_msgs/msg/PoseArray"
"""A body tracker's keypoints, as the tracker takes them from ROS 2 (:mod:`services.ros2.keypoints`)."""


def namespaced(namespace: str, name: str) -> str:
    """A topic's absolute name: ``name`` if absolute, else under ``namespace`` (``/cell`` + ``foresight/goal``)."""
    if name.startswith("/"):
        return name
    return "/" + "/".join(p for p in (*namespace.split("/"), *name.split("/")) if p)


def check_node_name(name: str, option: str) -> None:
    """Refuse a node name ROS 2 would refuse, naming ``option`` (``ros2.node``, ``simrobot.node``)."""
    if not ROS_NAME.fullmatch(name):
        raise ConfigError(f"{option}: a name of letters, digits and '_' not starting with a digit (ROS 2's rule), "
                          f"got {name!r}")


@dataclass
class Ros2Config:
    """Options of ``foresight ros2`` (``[ros2]``)."""

    domain_id: int = opt(default_factory=lambda: ros_domain_id(), help="ROS 2 domain id (default: $ROS_DOMAIN_ID, "
                         "else 0)")
    namespace: str = opt("/", help="namespace of the node and of its relative topics")
    node: str = opt("foresight", help="ROS 2 node name")
    frame_id: str = opt("world", help="frame of the markers and the trajectory header (the scene's frame)")
    joint_states: bool = opt(True, help="publish /joint_states from Foresight's executor (off when a real robot "
                             "publishes them)")
    clock: bool = opt(True, help="in a lock-step run, publish its simulated time on /clock (RViz and other nodes "
                      "with use_sim_time follow it; the messages' stamps are that time, from 0)")
    min_probability: float = opt(0.05, help="occupancy markers: voxels below this probability are left out")
    log_level: str = opt("INFO", choices=LOG_LEVELS, help="log level")

    def validate(self) -> None:
        """Check ranges and names."""
        check_domain_id(self.domain_id, "ros2.domain_id", "--domain-id")
        parts = self.namespace.rstrip("/")[1:].split("/") if self.namespace != "/" else []  # '//a': an empty part
        if not self.namespace.startswith("/") or not all(ROS_NAME.fullmatch(p) for p in parts):
            raise ConfigError(f"ros2.namespace: '/' or /name/... with names of letters, digits and '_' not "
                              f"starting with a digit (ROS 2's rule), got {self.namespace!r}")
        check_node_name(self.node, "ros2.node")
        if not 0.0 <= self.min_probability <= 1.0:
            raise ConfigError(f"ros2.min_probability: must be in [0, 1], got {self.min_probability}")
        if not self.frame_id.strip():
            raise ConfigError("ros2.frame_id: empty (RViz refuses markers without a frame); the scene's frame is "
                              "'world'")

    @property
    def node_namespace(self) -> str:
        """The namespace as ROS 2 writes it: ``/`` or ``/a/b``, without a trailing ``/`` (``/a/`` is ``/a``)."""
        return "/" + "/".join(p for p in self.namespace.split("/") if p)

    def enabled(self, role: str) -> bool:
        """Whether ``role``'s topic is published (the joint states and the clock may be turned off)."""
        return {"joint_states": self.joint_states, "clock": self.clock}.get(role, True)

    def topic(self, role: str) -> str:
        """The absolute topic name of ``role``."""
        return namespaced(self.namespace, TOPICS[role].name)


def _sec_nanosec(seconds: float) -> tuple[int, int]:
    """Seconds as whole seconds and nanoseconds, rounded to the nanosecond (2.9999999999999996 -> (3, 0))."""
    return divmod(int(round(seconds * 1e9)), 10**9)


def time_msg(ts: Any, seconds: float) -> Any:
    """A ``builtin_interfaces/msg/Time`` of ``seconds``, rounded to the nanosecond (``ts``: the type store)."""
    sec, nanosec = _sec_nanosec(seconds)
    return ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _duration(ts: Any, seconds: float) -> Any:
    sec, nanosec = _sec_nanosec(seconds)
    return ts.types["builtin_interfaces/msg/Duration"](sec=sec, nanosec=nanosec)


def seconds_in(time: Any, what: str) -> float:
    """Seconds of a received ``builtin_interfaces`` ``Time`` or ``Duration``; ``what`` names the field.

    Raises:
        Ros2InputError: ``nanosec`` outside [0, 1e9), which the message definition excludes (1.5e9 would be
            read as 1.5 s more than the sender's clock library means).
    """
    if not 0 <= time.nanosec < 10**9:
        raise Ros2InputError(f"{what}: nanosec {time.nanosec} outside 0..999999999 (sec {time.sec})")
    return time.sec + time.nanosec * 1e-9


class Ros2Mapping:
    """Encodes Foresight messages as ROS 2 CDR payloads and decodes what comes in, with the type store's hashes.

    Args:
        config: Topic names, frame, thresholds.
    """

    def __init__(self, config: Ros2Config) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.config = config
        self.ts = get_typestore(Stores.ROS2_JAZZY)
        types = {t.msgtype for t in TOPICS.values()} | set(ROBOT_TYPES.values()) | {KEYPOINTS_TYPE}
        self.hashes = {msgtype: self.ts.hash_rihs01(msgtype) for msgtype in sorted(types)}

    # -- keys -------------------------------------------------------------------------------------------------

    def key(self, role: str) -> str:
        """The Zenoh data key of a published topic."""
        t = TOPICS[role]
        return data_key(self.config.domain_id, self.config.topic(role), t.msgtype, self.hashes[t.msgtype])

    def _header(self, stamp: float) -> Any:
        return self.ts.types["std_msgs/msg/Header"](stamp=time_msg(self.ts, stamp), frame_id=self.config.frame_id)

    def _cdr(self, msg: Any, msgtype: str) -> bytes:
        return bytes(self.ts.serialize_cdr(msg, msgtype))

    # -- Foresight -> ROS 2 -----------------------------------------------------------------------------------

    def trajectory(self, plan: Plan) -> bytes:
        """The chosen goal's trajectory as ``JointTrajectory`` (``time_from_start`` = waypoint x ``plan.dt``)."""
        ts = self.ts
        traj = np.asarray(plan.trajectories[plan.chosen], dtype=np.float64)  # (T, D)
        point = ts.types["trajectory_msgs/msg/JointTrajectoryPoint"]
        empty = np.zeros(0, dtype=np.float64)
        points = [point(positions=q.copy(), velocities=empty, accelerations=empty, effort=empty,
                        time_from_start=_duration(ts, i * float(plan.dt))) for i, q in enumerate(traj)]
        msg = ts.types["trajectory_msgs/msg/JointTrajectory"](header=self._header(plan.stamp),
                                                              joint_names=list(plan.joint_names), points=points)
        return self._cdr(msg, TOPICS["trajectory"].msgtype)

    def goal(self, plan: Plan) -> bytes:
        """The chosen goal's name as ``std_msgs/String``."""
        msg = self.ts.types["std_msgs/msg/String"](data=plan.goal_names[plan.chosen])
        return self._cdr(msg, TOPICS["goal"].msgtype)

    def joint_state(self, state: RobotState) -> bytes:
        """The simulated robot's state as ``JointState`` (positions and velocities)."""
        return self.joint_state_of(list(state.joint_names), state.q, state.qd, state.stamp)

    def command(self, joint_names: list[str], positions: np.ndarray, times: np.ndarray) -> bytes:
        """A command to a ``joint_trajectory_controller``: ``JointTrajectory`` with a zero header stamp (start now).

        Args:
            joint_names: ``D`` names, the columns of ``positions``.
            positions: ``(N, D)`` waypoints.
            times: ``(N,)`` their ``time_from_start``, seconds, increasing.
        """
        ts = self.ts
        point = ts.types["trajectory_msgs/msg/JointTrajectoryPoint"]
        empty = np.zeros(0, dtype=np.float64)
        points = [point(positions=np.asarray(q, np.float64).copy(), velocities=empty, accelerations=empty,
                        effort=empty, time_from_start=_duration(ts, float(t))) for q, t in zip(positions, times,
                                                                                             strict=True)]
        msg = ts.types["trajectory_msgs/msg/JointTrajectory"](header=self._header(0.0), joint_names=list(joint_names),
                                                              points=points)
        return self._cdr(msg, ROBOT_TYPES["command"])

    def clock(self, t: float) -> bytes:
        """Simulated time as ``rosgraph_msgs/Clock`` (what ROS 2 nodes with ``use_sim_time`` follow)."""
        return self._cdr(self.ts.types["rosgraph_msgs/msg/Clock"](clock=time_msg(self.ts, t)), ROBOT_TYPES["clock"])

    def joint_state_of(self, joint_names: list[str], q: np.ndarray, qd: np.ndarray, stamp: float) -> bytes:
        """A robot's ``JointState`` (positions, velocities) at ``stamp``."""
        msg = self.ts.types["sensor_msgs/msg/JointState"](
            header=self._header(stamp), name=list(joint_names), position=np.asarray(q, np.float64),
            velocity=np.asarray(qd, np.float64), effort=np.zeros(0, dtype=np.float64))
        return self._cdr(msg, ROBOT_TYPES["state"])

    def _marker(self, ns: str, marker_id: int, kind: int, stamp: float, scale: float, points: np.ndarray,
                colors: np.ndarray) -> Any:
        t = self.ts.types
        pose = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                           orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        point, color = t["geometry_msgs/msg/Point"], t["std_msgs/msg/ColorRGBA"]
        return t["visualization_msgs/msg/Marker"](
            header=self._header(stamp), ns=ns, id=marker_id, type=kind, action=0, pose=pose,
            scale=t["geometry_msgs/msg/Vector3"](x=scale, y=scale, z=scale),
            color=color(r=1.0, g=1.0, b=1.0, a=1.0), lifetime=_duration(self.ts, 0.0), frame_locked=False,
            points=[point(x=float(x), y=float(y), z=float(z)) for x, y, z in points],
            colors=[color(r=float(r), g=float(g), b=float(b), a=float(a)) for r, g, b, a in colors],
            texture_resource="", texture=t["sensor_msgs/msg/CompressedImage"](
                header=self._header(stamp), format="", data=np.zeros(0, np.uint8)),
            uv_coordinates=[], text="", mesh_resource="",
            mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
            mesh_use_embedded_materials=False)

    def occupancy(self, grid: OccupancyGrid) -> bytes:
        """The predicted occupancy as one ``CUBE_LIST`` marker, each voxel coloured by its probability."""
        p = grid.values.astype(np.float64) / 255.0
        keep = p >= self.config.min_probability
        ijk = np.stack(np.unravel_index(grid.indices[keep].astype(np.int64), tuple(int(d) for d in grid.dims)), -1)
        centres = np.asarray(grid.origin) + grid.resolution * (ijk + 0.5)
        pk = p[keep]
        colors = np.stack([np.ones_like(pk), 1.0 - pk, np.zeros_like(pk), 0.15 + 0.6 * pk], -1)  # yellow -> red
        marker = self._marker("occupancy", 0, 6, grid.stamp, float(grid.resolution), centres.reshape(-1, 3), colors)
        msg = self.ts.types["visualization_msgs/msg/MarkerArray"](markers=[marker])
        return self._cdr(msg, TOPICS["occupancy"].msgtype)

    def human(self, pose: HumanPose, placed_features: np.ndarray) -> bytes:
        """The human's body (placed in the scene) as a ``LINE_LIST`` of its capsules' axes.

        Args:
            pose: The pose message (its stamp).
            placed_features: ``(12,)`` the pose's features placed in the scene (``shared.human.place_in_scene``).
        """
        from shared.human import HumanModel

        ends, _ = HumanModel().capsules(placed_features)
        points = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
        colors = np.tile([0.95, 0.72, 0.62, 1.0], (len(points), 1))
        marker = self._marker("human", 0, 5, pose.stamp, 0.06, points, colors)
        msg = self.ts.types["visualization_msgs/msg/MarkerArray"](markers=[marker])
        return self._cdr(msg, TOPICS["human"].msgtype)

    def posterior(self, post: ClassPosterior) -> bytes:
        """The class posterior as a ``DiagnosticStatus``: one key-value per class, the best class as message.

        ``level`` is OK (0) for a familiar motion and WARN (1) for one unlike every class
        (``ClassPosterior.familiar``): then the best class is only the least unlikely.
        """
        t = self.ts.types
        best = int(np.argmax(post.posterior))
        values = [t["diagnostic_msgs/msg/KeyValue"](key=name, value=f"{float(p):.6f}")
                  for name, p in zip(post.class_names, post.posterior, strict=True)]
        level = 0 if post.familiar else 1
        msg = t["diagnostic_msgs/msg/DiagnosticStatus"](level=level, name="foresight/posterior",
                                                         message=post.class_names[best], hardware_id="",
                                                         values=values)
        return self._cdr(msg, TOPICS["posterior"].msgtype)

    # -- ROS 2 -> Foresight -----------------------------------------------------------------------------------

    def decode(self, payload: bytes, msgtype: str) -> Any:
        """Deserialize a CDR payload of ``msgtype``; raises :class:`Ros2InputError` naming what is wrong."""
        if len(payload) < 4 or payload[:2] not in (b"\x00\x01", b"\x00\x00"):
            raise Ros2InputError(f"{msgtype}: not CDR (encapsulation header {payload[:4].hex() or 'missing'})")
        try:
            return self.ts.deserialize_cdr(payload, msgtype)
        except Exception as exc:  # rosbags raises several types for truncated or garbled bytes
            raise Ros2InputError(f"{msgtype}: cannot be decoded ({type(exc).__name__}: {exc})") from None

    def joint_state_in(self, payload: bytes, joint_names: list[str]) -> tuple[float, np.ndarray, np.ndarray] | None:
        """A robot's ``JointState`` as ``(stamp s, q, qd)`` in ``joint_names``' order (qd zero where not sent or NaN).

        None for a state of none of ``joint_names``: another driver's joints on the same topic (a gripper's), as
        common on real robots; not an error.

        Raises:
            Ros2InputError: Not a JointState, some but not all joints of ``joint_names``, one of them repeated,
                lengths that disagree, a NaN or infinite position, a stamp's nanosec outside [0, 1e9). A non-finite
                velocity is a velocity not measured (joint_state_broadcaster's NaN): 0.
        """
        msg = self.decode(payload, "sensor_msgs/msg/JointState")
        names = list(msg.name)
        pos, vel = np.asarray(msg.position, dtype=np.float64), np.asarray(msg.velocity, dtype=np.float64)
        if len(pos) != len(names) or len(vel) not in (0, len(names)):
            raise Ros2InputError(f"JointState: {len(names)} names but {len(pos)} positions, {len(vel)} velocities")
        missing = [n for n in joint_names if n not in names]
        if len(missing) == len(joint_names):
            return None
        if missing:
            raise Ros2InputError(f"JointState: joints {missing} missing (has {names})")
        repeated = sorted({n for n in joint_names if names.count(n) > 1})
        if repeated:
            raise Ros2InputError(f"JointState: joints {repeated} repeated (which value holds?)")
        order = [names.index(n) for n in joint_names]
        q, qd = pos[order], (vel[order] if len(vel) else np.zeros(len(order)))
        if not np.all(np.isfinite(q)):
            bad = [n for n, v in zip(joint_names, q, strict=True) if not np.isfinite(v)]
            raise Ros2InputError(f"JointState: non-finite position of {bad}")
        # a velocity not measured: ros2_controllers' joint_state_broadcaster sends NaN for a joint without a velocity
        # interface (position-only arms, mock hardware), as it sends every joint's velocity; read as not moving
        qd = np.where(np.isfinite(qd), qd, 0.0)
        return seconds_in(msg.header.stamp, "JointState: header.stamp"), q, qd

    def trajectory_in(self, payload: bytes, joint_names: list[str]) -> tuple[list[int], np.ndarray, np.ndarray]:
        """A ``JointTrajectory`` command for a controller of ``joint_names``: ``(columns, positions, times)``.

        Returns:
            ``columns``: for each of the message's joints its index in ``joint_names``; ``positions``
            ``(N, len(columns))``, N >= 1; ``times`` ``(N,)`` seconds from the start, increasing.

        Raises:
            Ros2InputError: No joint names, no points (ros2_controllers' JointTrajectoryController refuses an
                empty trajectory, "Empty trajectory received.", and goes on with the one it has), a joint the
                controller does not have, a point of the wrong length, NaN, times not increasing.
        """
        msg = self.decode(payload, ROBOT_TYPES["command"])
        names = list(msg.joint_names)
        if not names:  # as ros2_controllers' trajectory controller: a command names the joints it moves
            raise Ros2InputError("JointTrajectory: no joint_names (a command names the joints it moves)")
        if not msg.points:
            raise Ros2InputError("JointTrajectory: no points (a trajectory controller refuses an empty trajectory and "
                                 "goes on with the one it has; to hold, send one point where the arm is)")
        unknown = [n for n in names if n not in joint_names]
        if unknown or len(set(names)) != len(names):
            raise Ros2InputError(f"JointTrajectory: joints {unknown or names} unknown or repeated (controller has "
                                 f"{joint_names})")
        if any(len(p.positions) != len(names) for p in msg.points):
            raise Ros2InputError(f"JointTrajectory: a point without {len(names)} positions")
        positions = np.array([p.positions for p in msg.points], dtype=np.float64).reshape(-1, len(names))
        times = np.array([seconds_in(p.time_from_start, f"JointTrajectory: point {i} time_from_start")
                          for i, p in enumerate(msg.points)])
        if not np.all(np.isfinite(positions)):
            raise Ros2InputError("JointTrajectory: non-finite positions")
        if np.any(np.diff(times) <= 0) or (len(times) and times[0] < 0):
            raise Ros2InputError(f"JointTrajectory: time_from_start must increase from >= 0, got {times.tolist()}")
        return [joint_names.index(n) for n in names], positions, times

    def clock_in(self, payload: bytes) -> float:
        """Seconds of a ``rosgraph_msgs/Clock``."""
        return seconds_in(self.decode(payload, ROBOT_TYPES["clock"]).clock, "Clock: clock")

    def robot_key(self, topic: str, role: str, type_hash: str | None = None) -> str:
        """The data key of a robot topic (``role`` in :data:`ROBOT_TYPES`); ``type_hash="*"`` matches any hash."""
        msgtype = ROBOT_TYPES[role]
        return data_key(self.config.domain_id, topic, msgtype, type_hash or self.hashes[msgtype])
