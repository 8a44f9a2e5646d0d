"""The message types of the wire contract, one dataclass each (fields, dtypes, shapes, invariants).

docs/protocol.md documents every field with its unit and who publishes and subscribes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .limits import MAX_GRID_CELLS, MAX_GRID_DIM
from .schema import Message, added, array
from .schema import field_error as _err

__all__ = ["N_FEATURES", "DEMO_EVENTS", "AT_REST", "HumanKeypoints", "HumanPose", "DemoMarker", "ClassPosterior",
           "OccupancyGrid", "Plan", "RobotState",
           "ClockTick", "MESSAGE_TYPES"]

N_FEATURES = 12


def _distinct(message: str, field: str, names: list[str]) -> None:
    """Refuse repeated or empty names: every receiver keys on them (joints, classes, goals, keypoints)."""
    if len(set(names)) != len(names) or not all(names):
        raise _err(message, field, "must be distinct and non-empty")


@dataclass
class HumanKeypoints(Message):
    """One frame of a body tracker: 3D positions of named body points (the tracker's input).

    ``names[j]`` names the point whose position is ``positions[j]`` (m, in the coordinate frame
    ``frame_id``); a point the sensor lost this frame is NaN (all three coordinates). Names are the
    sensor layout's (docs/keypoints.md): the tracker maps them to the human model's points. ``frame``
    numbers the sensor's frames (strictly increasing per sender; a gap is a dropped frame). ``tick``
    is -1 (a sensor runs in real time).
    """

    TYPE: ClassVar[str] = "HumanKeypoints"
    stamp: float
    tick: int
    frame: int
    frame_id: str
    names: list[str]
    positions: np.ndarray = array("float64", "J", 3, finite=False)

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        n = self.positions.shape[0]
        if len(self.names) != n or n == 0:
            raise _err(self.TYPE, "names", f"has {len(self.names)} names for {n} points (at least one point)")
        _distinct(self.TYPE, "names", self.names)
        if self.frame < 0:
            raise _err(self.TYPE, "frame", f"must be >= 0, got {self.frame}")
        partial = np.isnan(self.positions).any(axis=1) & ~np.isnan(self.positions).all(axis=1)
        if np.any(np.isinf(self.positions)) or np.any(partial):
            raise _err(self.TYPE, "positions", "a point is finite (x, y, z) or missing (NaN, NaN, NaN); "
                       "infinity or a partly NaN point is neither", "non-finite")


@dataclass
class HumanPose(Message):
    """One posture of the human (the replayer publishes one per sample).

    ``features`` are the paper's 12 joint features in the recorder's frame, in this order:
    pelvis x, y, z (m), pelvis yaw, torso X, Y, Z, right shoulder X, Z, Y (rad), right arm
    translation (m), right elbow Z (rad). ``tick_last`` is true on the last pose the replayer
    publishes for lock-step tick ``tick`` (always true in real-time mode, where ``tick`` is -1).
    """

    TYPE: ClassVar[str] = "HumanPose"
    stamp: float
    tick: int
    tick_last: bool
    demo_id: int
    index: int
    features: np.ndarray = array("float64", N_FEATURES)

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if self.index < 0:
            raise _err(self.TYPE, "index", f"must be >= 0, got {self.index}")


DEMO_EVENTS = ("start", "end", "lost")
"""A ``DemoMarker``'s events: a demonstration (a reach) starts, ends, or is lost, mid-way or after its end (the tracker
lost the person, or they moved away from where it showed them: where they are is unknown). ``lost`` came with schema
version 2 (:data:`EVENT_SINCE`)."""

EVENT_SINCE = {"lost": 2}
"""The schema version that added each later ``DemoMarker`` event: an older message carrying it is refused."""

AT_REST = "rest"
"""The ``class_name`` of a live tracker's demonstration of the person seen at rest (no reach): its poses are those
of the person standing still before any reach of a track (the first one, or the one after a loss), so the predictor
predicts from where the person really is and the robot need not wait for the first reach (docs/keypoints.md)."""


@dataclass
class DemoMarker(Message):
    """Start, end or loss (:data:`DEMO_EVENTS`) of a streamed demonstration. ``true_class`` is for evaluation only."""

    TYPE: ClassVar[str] = "DemoMarker"
    stamp: float
    tick: int
    demo_id: int
    event: str
    true_class: int
    class_name: str
    n_samples: int

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if self.event not in DEMO_EVENTS:
            raise _err(self.TYPE, "event", f"must be one of {', '.join(map(repr, DEMO_EVENTS))}, got {self.event!r}")
        if self.n_samples < 0:
            raise _err(self.TYPE, "n_samples", f"must be >= 0, got {self.n_samples}")

    def since(self) -> int:
        """The version that added this marker's event (``lost``: 2; :data:`EVENT_SINCE`)."""
        return EVENT_SINCE.get(self.event, 1)

    def check_version(self, version: int) -> None:
        """Refuse an event added after ``version`` (``lost``: 2), reason ``version``: its sender knew no such event."""
        since = self.since()
        if version < since:
            raise _err(self.TYPE, "event", f"{self.event!r} came with schema version {since}; this message is "
                       f"version {version}", "version")


@dataclass
class ClassPosterior(Message):
    """The predictor's belief over the M motion classes after pose ``index`` of ``demo_id``.

    ``familiar`` says whether any class explains the motion's last frames (its ``familiarity``, nats per frame,
    at or above the model's novelty threshold): the posterior sums to 1 for a motion unlike every class too.
    Both were added in schema version 2; a version-1 message is familiar with familiarity 0.
    """

    TYPE: ClassVar[str] = "ClassPosterior"
    stamp: float
    tick: int
    demo_id: int
    index: int
    class_names: list[str]
    posterior: np.ndarray = array("float64", "M")
    log_likelihood: np.ndarray = array("float64", "M", finite=False)
    familiar: bool = added(2, True)
    familiarity: float = added(2, 0.0)

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if len(self.class_names) != self.posterior.shape[0]:
            raise _err(self.TYPE, "class_names", f"has {len(self.class_names)} names for "
                       f"{self.posterior.shape[0]} classes")
        _distinct(self.TYPE, "class_names", self.class_names)  # a chart by name merged ["a", "a"] into one
        if np.any(self.posterior < 0) or abs(float(self.posterior.sum()) - 1.0) > 1e-6:
            raise _err(self.TYPE, "posterior", "must be non-negative and sum to 1")
        if np.any(np.isnan(self.log_likelihood)) or np.any(self.log_likelihood == np.inf):
            raise _err(self.TYPE, "log_likelihood", "contains NaN or +inf")


@dataclass
class OccupancyGrid(Message):
    """Predicted workspace occupancy p(x|xi), sparse and quantised.

    The grid has ``dims`` = (nx, ny, nz) voxels of edge ``resolution`` (m); voxel (i, j, k) has its
    lower corner at ``origin + resolution * (i, j, k)`` in the scene frame. Only voxels with
    non-zero probability are sent: ``indices`` are C-order flat indices ``(i * ny + j) * nz + k`` and
    ``values`` their probability quantised as ``round(255 * p)``. ``tick``, ``tick_last``,
    ``demo_id`` and ``index`` are copied from the pose the prediction was made from.
    """

    TYPE: ClassVar[str] = "OccupancyGrid"
    stamp: float
    tick: int
    tick_last: bool
    demo_id: int
    index: int
    method: str
    resolution: float
    origin: np.ndarray = array("float64", 3)
    dims: np.ndarray = array("int32", 3)
    indices: np.ndarray = array("uint32", "N")
    values: np.ndarray = array("uint8", "N")

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if self.method not in ("prediction", "current"):
            raise _err(self.TYPE, "method", f"must be 'prediction' or 'current', got {self.method!r}")
        if not (self.resolution > 0 and math.isfinite(self.resolution)):
            raise _err(self.TYPE, "resolution", f"must be > 0, got {self.resolution}")
        n = self.cells()
        if self.indices.size > n:
            raise _err(self.TYPE, "indices", f"{self.indices.size} voxels sent for a grid of {n}")
        if self.indices.size and int(self.indices.max()) >= n:
            raise _err(self.TYPE, "indices", f"index {int(self.indices.max())} outside a grid of {n} voxels")
        if np.any(np.diff(self.indices.astype(np.int64)) <= 0):  # [1, 1]: the voxel drawn twice, the last value kept
            raise _err(self.TYPE, "indices", "must be strictly increasing (each voxel once)")
        if np.any(self.values == 0):
            raise _err(self.TYPE, "values", "only voxels of non-zero probability are sent")

    def cells(self) -> int:
        """``nx * ny * nz``, after checking the declared dims against the limits (nothing allocated).

        Raises:
            ProtocolError: A dim <= 0, over ``MAX_GRID_DIM``, or more than ``MAX_GRID_CELLS`` voxels.
        """
        dims = [int(d) for d in np.asarray(self.dims).reshape(-1)]
        if len(dims) != 3 or any(d <= 0 for d in dims):
            raise _err(self.TYPE, "dims", f"must be 3 positive sizes, got {dims}")
        if max(dims) > MAX_GRID_DIM or math.prod(dims) > MAX_GRID_CELLS:
            raise _err(self.TYPE, "dims", f"{dims} exceeds the limits ({MAX_GRID_DIM} per axis, "
                       f"{MAX_GRID_CELLS} voxels)", "too-large")
        return math.prod(dims)

    @classmethod
    def from_dense(cls, grid: np.ndarray, origin: np.ndarray, resolution: float, **meta: Any) -> OccupancyGrid:
        """Quantise and sparsify a dense probability grid.

        Args:
            grid: ``(nx, ny, nz)`` probabilities in [0, 1].
            origin: ``(3,)`` lower corner of voxel (0, 0, 0), metres.
            resolution: Voxel edge, metres.
            **meta: The remaining fields (stamp, tick, demo_id, index, method).
        """
        q = np.rint(np.clip(grid, 0.0, 1.0) * 255.0).astype(np.uint8).ravel()
        idx = np.flatnonzero(q).astype(np.uint32)
        return cls(resolution=float(resolution), origin=np.asarray(origin, dtype=np.float64),
                   dims=np.asarray(grid.shape, dtype=np.int32), indices=idx, values=q[idx], **meta)

    def to_dense(self, dtype: Any = np.float32) -> np.ndarray:
        """Return the ``(nx, ny, nz)`` probability grid (values ``q / 255``).

        The declared size is checked against the limits before anything is allocated.

        Raises:
            ProtocolError: If the dims exceed the limits or an index lies outside the grid.
        """
        n = self.cells()
        if self.indices.size and int(self.indices.max()) >= n:
            raise _err(self.TYPE, "indices", f"index {int(self.indices.max())} outside a grid of {n} voxels")
        out = np.zeros(n, dtype=dtype)
        out[self.indices.astype(np.int64)] = self.values.astype(dtype) / dtype(255.0)
        return out.reshape(tuple(int(d) for d in self.dims))


@dataclass
class Plan(Message):
    """One replanning step: all K candidate trajectories, their cost terms and the chosen goal.

    ``trajectories[k]`` has T waypoints of the D joints in ``joint_names``, ``dt`` seconds apart,
    starting at the configuration the robot will have when this plan starts executing. Goals that
    could not be planned (e.g. IK failed) have ``valid[k] = False``, cost ``+inf`` and are never
    chosen; valid goals have finite costs. ``occupancy_tick`` / ``occupancy_index`` identify the
    prediction the costs were computed on.
    """

    TYPE: ClassVar[str] = "Plan"
    stamp: float
    tick: int
    step: int
    goal_names: list[str]
    joint_names: list[str]
    dt: float
    chosen: int
    planning_ms: float
    occupancy_tick: int
    occupancy_index: int
    trajectories: np.ndarray = array("float32", "K", "T", "D")
    cost_smoothness: np.ndarray = array("float64", "K", finite=False)
    cost_obstacle: np.ndarray = array("float64", "K", finite=False)
    cost_human: np.ndarray = array("float64", "K", finite=False)
    cost_total: np.ndarray = array("float64", "K", finite=False)
    valid: np.ndarray = array("bool", "K")

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        k, t, d = self.trajectories.shape
        if t < 2:
            raise _err(self.TYPE, "trajectories", f"has {t} waypoint(s) per trajectory; at least 2 (its start and end)")
        if len(self.goal_names) != k:
            raise _err(self.TYPE, "goal_names", f"has {len(self.goal_names)} names for {k} trajectories")
        if len(self.joint_names) != d:
            raise _err(self.TYPE, "joint_names", f"has {len(self.joint_names)} names for {d} joints")
        if d == 0:
            raise _err(self.TYPE, "trajectories", "has no joints; a robot has at least 1")
        _distinct(self.TYPE, "goal_names", self.goal_names)
        _distinct(self.TYPE, "joint_names", self.joint_names)  # the ROS 2 gateway sent on what its parsers refuse
        if not (0 <= self.chosen < k) or not bool(self.valid[self.chosen]):
            raise _err(self.TYPE, "chosen", f"{self.chosen} is not a valid goal index")
        for name in ("cost_smoothness", "cost_obstacle", "cost_human", "cost_total"):
            cost = getattr(self, name)
            if not np.all(np.isfinite(cost[self.valid])) or not np.all(cost[~self.valid] == np.inf):
                raise _err(self.TYPE, name, "must be finite for valid goals and +inf for invalid ones")
        if not (self.dt > 0 and math.isfinite(self.dt)):
            raise _err(self.TYPE, "dt", f"must be > 0, got {self.dt}")


@dataclass
class RobotState(Message):
    """The simulated robot's state, published by the executor at a fixed rate.

    ``goal`` is the index of the goal being executed (-1 before the first plan); ``holding`` is true
    when the executor holds the robot still because its inputs are stale, with ``reason`` saying why.
    """

    TYPE: ClassVar[str] = "RobotState"
    stamp: float
    tick: int
    joint_names: list[str]
    goal: int
    reached: bool
    holding: bool
    reason: str
    q: np.ndarray = array("float64", "D")
    qd: np.ndarray = array("float64", "D")

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if len(self.joint_names) != self.q.shape[0]:
            raise _err(self.TYPE, "joint_names", f"has {len(self.joint_names)} names for {self.q.shape[0]} joints")
        if self.q.shape[0] == 0:
            raise _err(self.TYPE, "q", "has no joints; a robot has at least 1")
        _distinct(self.TYPE, "joint_names", self.joint_names)


@dataclass
class ClockTick(Message):
    """Lock-step clock: tick n starts replanning step n at simulated time ``stamp``."""

    TYPE: ClassVar[str] = "ClockTick"
    stamp: float
    tick: int
    period: float

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if self.tick < 0:
            raise _err(self.TYPE, "tick", f"must be >= 0, got {self.tick}")
        if not (self.period > 0 and math.isfinite(self.period)):
            raise _err(self.TYPE, "period", f"must be > 0, got {self.period}")


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls
    for cls in (HumanKeypoints, HumanPose, DemoMarker, ClassPosterior, OccupancyGrid, Plan, RobotState, ClockTick)
}
