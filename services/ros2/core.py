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
=========================  ==========================================  =========================================

Frames: everything in the scene's frame, ``frame_id`` (default ``world``, as in the MCAP's scene).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from shared.config import ConfigError, opt
from shared.protocol import ClassPosterior, HumanPose, OccupancyGrid, Plan, RobotState

from .wire import data_key

__all__ = ["Ros2Config", "Ros2Mapping", "Topic", "TOPICS", "Ros2InputError"]

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
}
"""What the ``ros2`` service publishes, by role."""


@dataclass
class Ros2Config:
    """Options of ``foresight ros2`` (``[ros2]``)."""

    domain_id: int = opt(0, help="ROS 2 domain id (ROS_DOMAIN_ID)")
    namespace: str = opt("/", help="namespace of the node and of its relative topics")
    node: str = opt("foresight", help="ROS 2 node name")
    frame_id: str = opt("world", help="frame of the markers and the trajectory header (the scene's frame)")
    joint_states: bool = opt(True, help="publish /joint_states from Foresight's executor (off when a real robot "
                             "publishes them)")
    min_probability: float = opt(0.05, help="occupancy markers: voxels below this probability are left out")
    log_level: str = opt("INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"), help="log level")

    def validate(self) -> None:
        """Check ranges and names."""
        if not 0 <= self.domain_id <= 232:
            raise ConfigError(f"ros2.domain_id: must be 0..232, got {self.domain_id}")
        if not self.namespace.startswith("/"):
            raise ConfigError(f"ros2.namespace: must start with '/', got {self.namespace!r}")
        if not self.node or "/" in self.node:
            raise ConfigError(f"ros2.node: a name without '/', got {self.node!r}")
        if not 0.0 <= self.min_probability <= 1.0:
            raise ConfigError(f"ros2.min_probability: must be in [0, 1], got {self.min_probability}")

    def topic(self, role: str) -> str:
        """The absolute topic name of ``role``."""
        name = TOPICS[role].name
        if name.startswith("/"):
            return name
        return "/" + "/".join(p for p in (*self.namespace.split("/"), *name.split("/")) if p)


def _stamp(ts: Any, seconds: float) -> Any:
    sec = math.floor(seconds)
    return ts.types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(round((seconds - sec) * 1e9)) % 10**9)


def _duration(ts: Any, seconds: float) -> Any:
    sec = math.floor(seconds)
    return ts.types["builtin_interfaces/msg/Duration"](sec=int(sec),
                                                      nanosec=int(round((seconds - sec) * 1e9)) % 10**9)


class Ros2Mapping:
    """Encodes Foresight messages as ROS 2 CDR payloads and decodes what comes in, with the type store's hashes.

    Args:
        config: Topic names, frame, thresholds.
    """

    def __init__(self, config: Ros2Config) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.config = config
        self.ts = get_typestore(Stores.ROS2_JAZZY)
        self.hashes = {t.msgtype: self.ts.hash_rihs01(t.msgtype) for t in TOPICS.values()}

    # -- keys -------------------------------------------------------------------------------------------------

    def key(self, role: str) -> str:
        """The Zenoh data key of a published topic."""
        t = TOPICS[role]
        return data_key(self.config.domain_id, self.config.topic(role), t.msgtype, self.hashes[t.msgtype])

    def _header(self, stamp: float) -> Any:
        return self.ts.types["std_msgs/msg/Header"](stamp=_stamp(self.ts, stamp), frame_id=self.config.frame_id)

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
        empty = np.zeros(0, dtype=np.float64)
        msg = self.ts.types["sensor_msgs/msg/JointState"](
            header=self._header(state.stamp), name=list(state.joint_names),
            position=np.asarray(state.q, np.float64), velocity=np.asarray(state.qd, np.float64), effort=empty)
        return self._cdr(msg, TOPICS["joint_states"].msgtype)

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
        """The class posterior as a ``DiagnosticStatus``: one key-value per class, the best class as message."""
        t = self.ts.types
        best = int(np.argmax(post.posterior))
        values = [t["diagnostic_msgs/msg/KeyValue"](key=name, value=f"{float(p):.6f}")
                  for name, p in zip(post.class_names, post.posterior, strict=True)]
        msg = t["diagnostic_msgs/msg/DiagnosticStatus"](level=0, name="foresight/posterior",
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

    def joint_state_in(self, payload: bytes, joint_names: list[str]) -> tuple[float, np.ndarray]:
        """A robot's ``JointState`` as ``(stamp s, q in joint_names' order)``.

        Raises:
            Ros2InputError: Not a JointState, a joint of ``joint_names`` missing, lengths that disagree, NaN.
        """
        msg = self.decode(payload, "sensor_msgs/msg/JointState")
        names = list(msg.name)
        pos = np.asarray(msg.position, dtype=np.float64)
        if len(pos) != len(names):
            raise Ros2InputError(f"JointState: {len(names)} names but {len(pos)} positions")
        missing = [n for n in joint_names if n not in names]
        if missing:
            raise Ros2InputError(f"JointState: joints {missing} missing (has {names})")
        q = pos[[names.index(n) for n in joint_names]]
        if not np.all(np.isfinite(q)):
            bad = [n for n, v in zip(joint_names, q, strict=True) if not np.isfinite(v)]
            raise Ros2InputError(f"JointState: non-finite position of {bad}")
        return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, q
