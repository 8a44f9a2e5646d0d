"""The wire contract: key expressions and message schemas (documented in docs/protocol.md).

Every message is a msgpack map with ``_type`` (the message type name), ``_v`` (the schema version,
:data:`SCHEMA_VERSION`) and one entry per field. Numeric arrays travel as maps
``{"dtype": "<f8", "shape": [..], "data": <raw little-endian bytes>}``.

:func:`decode` validates everything (type, version, field presence, scalar types, array dtypes,
shapes and finiteness, and per-message invariants) and raises :class:`ProtocolError`, whose message
names the offending field.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import msgpack
import numpy as np

__all__ = [
    "SCHEMA_VERSION",
    "ProtocolError",
    "ArraySpec",
    "Message",
    "HumanPose",
    "DemoMarker",
    "ClassPosterior",
    "OccupancyGrid",
    "Plan",
    "RobotState",
    "ClockTick",
    "MESSAGE_TYPES",
    "Keys",
    "SERVICES",
    "encode",
    "decode",
]

SCHEMA_VERSION = 1
N_FEATURES = 12
SERVICES = ("replayer", "predictor", "planner", "executor")

M = TypeVar("M", bound="Message")


class ProtocolError(ValueError):
    """A message failed to decode or validate; the text names the offending field."""


@dataclass(frozen=True)
class ArraySpec:
    """Expected dtype and shape of an array field.

    Attributes:
        dtype: numpy dtype name, e.g. ``"float64"``; the wire dtype must match exactly.
        shape: One entry per axis: an int (fixed), or a symbol such as ``"K"`` that must take the same
            value in every field of the message where it appears.
        finite: Reject NaN and infinities (float dtypes only).
    """

    dtype: str
    shape: tuple[int | str, ...]
    finite: bool = True


def array(dtype: str, *shape: int | str, finite: bool = True) -> Any:
    """Declare an array field of a message dataclass."""
    return dataclasses.field(metadata={"array": ArraySpec(dtype, tuple(shape), finite)})


class Message:
    """Base of all message dataclasses. Subclasses set ``TYPE`` and may override :meth:`check`."""

    TYPE: ClassVar[str] = ""

    def check(self) -> None:
        """Per-message invariants beyond field types and shapes; raise ProtocolError."""


def _err(msg_type: str, field: str, text: str) -> ProtocolError:
    return ProtocolError(f"{msg_type}.{field}: {text}")


# ----------------------------------------------------------------------------------------------
# message types


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


@dataclass
class DemoMarker(Message):
    """Start or end of a streamed demonstration. ``true_class`` is for evaluation only."""

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
        if self.event not in ("start", "end"):
            raise _err(self.TYPE, "event", f"must be 'start' or 'end', got {self.event!r}")
        if self.n_samples < 0:
            raise _err(self.TYPE, "n_samples", f"must be >= 0, got {self.n_samples}")


@dataclass
class ClassPosterior(Message):
    """The predictor's belief over the M motion classes after pose ``index`` of ``demo_id``."""

    TYPE: ClassVar[str] = "ClassPosterior"
    stamp: float
    tick: int
    demo_id: int
    index: int
    class_names: list[str]
    posterior: np.ndarray = array("float64", "M")
    log_likelihood: np.ndarray = array("float64", "M", finite=False)

    def check(self) -> None:
        """Validate this message's invariants (see the class docstring)."""
        if len(self.class_names) != self.posterior.shape[0]:
            raise _err(self.TYPE, "class_names", f"has {len(self.class_names)} names for "
                       f"{self.posterior.shape[0]} classes")
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
        if np.any(self.dims <= 0):
            raise _err(self.TYPE, "dims", f"must be positive, got {self.dims.tolist()}")
        n = int(np.prod(self.dims.astype(np.int64)))
        if self.indices.size and int(self.indices.max()) >= n:
            raise _err(self.TYPE, "indices", f"index {int(self.indices.max())} outside a grid of {n} voxels")

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
        """Return the ``(nx, ny, nz)`` probability grid (values ``q / 255``)."""
        out = np.zeros(int(np.prod(self.dims.astype(np.int64))), dtype=dtype)
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
        k, _, d = self.trajectories.shape
        if len(self.goal_names) != k:
            raise _err(self.TYPE, "goal_names", f"has {len(self.goal_names)} names for {k} trajectories")
        if len(self.joint_names) != d:
            raise _err(self.TYPE, "joint_names", f"has {len(self.joint_names)} names for {d} joints")
        if not (0 <= self.chosen < k) or not bool(self.valid[self.chosen]):
            raise _err(self.TYPE, "chosen", f"{self.chosen} is not a valid goal index")
        for name in ("cost_smoothness", "cost_obstacle", "cost_human", "cost_total"):
            cost = getattr(self, name)
            if np.any(np.isnan(cost)) or not np.all(np.isfinite(cost[self.valid])) or np.any(cost == -np.inf):
                raise _err(self.TYPE, name, "must be finite for valid goals (+inf allowed for invalid ones), no NaN")
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
    for cls in (HumanPose, DemoMarker, ClassPosterior, OccupancyGrid, Plan, RobotState, ClockTick)
}


# ----------------------------------------------------------------------------------------------
# key expressions


class Keys:
    """Key expressions under a prefix (default ``foresight``).

    Args:
        prefix: Key prefix without trailing ``/``.
    """

    def __init__(self, prefix: str = "foresight") -> None:
        self.prefix = prefix
        self.pose = f"{prefix}/human/pose"
        self.demo = f"{prefix}/human/demo"
        self.posterior = f"{prefix}/prediction/posterior"
        self.occupancy = f"{prefix}/prediction/occupancy"
        self.plan = f"{prefix}/planner/plan"
        self.robot_state = f"{prefix}/robot/state"
        self.clock = f"{prefix}/clock/tick"
        self.alive_all = f"{prefix}/alive/*"
        self.human_all = f"{prefix}/human/*"  # poses and markers in one ordered subscription

    def alive(self, service: str) -> str:
        """Liveliness token key of a service."""
        return f"{self.prefix}/alive/{service}"

    def data_keys(self) -> dict[str, type[Message]]:
        """Every data key expression and the one message type it carries."""
        return {
            self.pose: HumanPose,
            self.demo: DemoMarker,
            self.posterior: ClassPosterior,
            self.occupancy: OccupancyGrid,
            self.plan: Plan,
            self.robot_state: RobotState,
            self.clock: ClockTick,
        }


# ----------------------------------------------------------------------------------------------
# encode / decode


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def encode(msg: Message) -> bytes:
    """Encode a message to msgpack bytes (validating it first, so bad data never leaves).

    Raises:
        ProtocolError: If the message does not satisfy its own schema.
    """
    out: dict[str, Any] = {"_type": msg.TYPE, "_v": SCHEMA_VERSION}
    for f in dataclasses.fields(msg):  # type: ignore[arg-type]
        value = getattr(msg, f.name)
        spec = f.metadata.get("array")
        if spec is not None:
            arr = np.ascontiguousarray(value, dtype=np.dtype(spec.dtype).newbyteorder("<"))
            out[f.name] = {"dtype": arr.dtype.str, "shape": list(arr.shape), "data": arr.tobytes()}
        elif isinstance(value, np.generic):
            out[f.name] = value.item()
        else:
            out[f.name] = value
    data = msgpack.packb(out, use_bin_type=True)
    decode(data, type(msg))  # one validation path for both directions
    return data


def _decode_array(t: str, name: str, raw: Any, spec: ArraySpec, dims: dict[str, int]) -> np.ndarray:
    if not isinstance(raw, dict) or set(raw) != {"dtype", "shape", "data"}:
        raise _err(t, name, "array must be a map with keys dtype, shape, data")
    try:
        dtype = np.dtype(raw["dtype"])
    except (TypeError, ValueError):
        raise _err(t, name, f"unknown dtype {raw['dtype']!r}") from None
    want = np.dtype(spec.dtype)
    if dtype.kind != want.kind or dtype.itemsize != want.itemsize:
        raise _err(t, name, f"dtype {dtype.name} where {want.name} is required")
    shape = raw["shape"]
    if not isinstance(shape, list) or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                              for s in shape):
        raise _err(t, name, f"shape {shape!r} is not a list of non-negative ints")
    if len(shape) != len(spec.shape):
        raise _err(t, name, f"shape {tuple(shape)} has {len(shape)} axes, expected {len(spec.shape)} "
                   f"{spec.shape}")
    for axis, (got, exp) in enumerate(zip(shape, spec.shape, strict=True)):
        if isinstance(exp, int):
            if got != exp:
                raise _err(t, name, f"shape {tuple(shape)} axis {axis} must be {exp}")
        elif exp in dims and dims[exp] != got:
            raise _err(t, name, f"shape {tuple(shape)} axis {axis} ({exp}) must be {dims[exp]} "
                       "like the other fields")
        else:
            dims[exp] = got
    data = raw["data"]
    if not isinstance(data, bytes | bytearray):
        raise _err(t, name, "data must be bytes")
    n = int(np.prod(shape, dtype=np.int64))
    if len(data) != n * dtype.itemsize:
        raise _err(t, name, f"data has {len(data)} bytes, shape {tuple(shape)} of {dtype.name} needs "
                   f"{n * dtype.itemsize}")
    arr = np.frombuffer(data, dtype=dtype).reshape(shape).astype(want, copy=True)
    if spec.finite and arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise _err(t, name, "contains NaN or infinity")
    return arr


def _check_scalar(t: str, name: str, tp: Any, value: Any) -> Any:
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _err(t, name, f"expected a number, got {type(value).__name__}")
        if not math.isfinite(value):
            raise _err(t, name, f"must be finite, got {value}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _err(t, name, f"expected an integer, got {type(value).__name__}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _err(t, name, f"expected a boolean, got {type(value).__name__}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _err(t, name, f"expected a string, got {type(value).__name__}")
        return value
    if typing.get_origin(tp) is list:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise _err(t, name, "expected a list of strings")
        return list(value)
    raise _err(t, name, f"unsupported field type {tp!r}")  # pragma: no cover


def decode(data: bytes | bytearray | memoryview, expected: type[M] | None = None) -> M:
    """Decode and validate msgpack bytes into a message.

    Args:
        data: The payload.
        expected: If given, the message must be of this type.

    Returns:
        The message dataclass instance.

    Raises:
        ProtocolError: On truncated/malformed bytes, unknown type, wrong version, a missing or
            ill-typed field, wrong dtype or shape, non-finite values or a broken invariant.
    """
    try:
        raw = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated types for bad input
        raise ProtocolError(f"message: not valid msgpack ({type(exc).__name__}: {exc})") from None
    if not isinstance(raw, dict):
        raise ProtocolError(f"message: expected a map, got {type(raw).__name__}")
    t = raw.get("_type")
    if t not in MESSAGE_TYPES:
        raise ProtocolError(f"message._type: unknown message type {t!r}")
    cls = MESSAGE_TYPES[t]
    if expected is not None and cls is not expected:
        raise ProtocolError(f"message._type: got {t}, expected {expected.TYPE}")
    if raw.get("_v") != SCHEMA_VERSION:
        raise ProtocolError(f"{t}._v: schema version {raw.get('_v')!r}, this build speaks {SCHEMA_VERSION}")
    hints = _hints(cls)
    kwargs: dict[str, Any] = {}
    dims: dict[str, int] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.name not in raw:
            raise _err(t, f.name, "missing")
        spec = f.metadata.get("array")
        if spec is not None:
            kwargs[f.name] = _decode_array(t, f.name, raw[f.name], spec, dims)
        else:
            kwargs[f.name] = _check_scalar(t, f.name, hints[f.name], raw[f.name])
    msg = cls(**kwargs)
    msg.check()
    return msg  # type: ignore[return-value]
