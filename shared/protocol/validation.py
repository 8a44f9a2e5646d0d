"""Value-level validation on receipt: what a decoded message's values must mean, and what the receiver expects.

:func:`~shared.protocol.codec.decode` checks the form (types, shapes, sizes, finiteness, invariants).
:func:`check_values` checks the meaning, against :class:`Expectations` the receiving service builds
from what it knows (its clock mode, its robot's joints and limits, its scene's grid):

* stamps: real time, a wall-clock stamp within ``STAMP_PAST_S`` before and ``STAMP_FUTURE_S`` after
  the receiver's clock, and ``tick == -1``; lock-step, a simulated stamp in ``[tick P, (tick + 1) P]``
  when the receiver knows the period P (the executor), else in ``[0, (tick + 1) MAX_PERIOD_S]``, and
  no tick beyond the lock-step clock (``max_tick``);
* ranges: features within their plausible human range, grid geometry (resolution, origin, the
  scene's grid), periods, waypoint spacing, planning time, costs (non-negative, bounded), counters;
* the robot: joint names equal to the receiver's, positions within its limits plus
  ``JOINT_LIMIT_TOL`` (every goal's waypoints, valid or not), velocities within its limits plus
  ``VELOCITY_LIMIT_TOL`` (without a model: ``MAX_ABS_JOINT`` / ``MAX_ABS_JOINT_VELOCITY``);
* keypoints: real time (``tick == -1``) whatever the receiver's clock: a sensor has no other.

Per-sender order (ticks, sequence numbers) is :mod:`shared.protocol.receipt`'s. Every failure is a
:class:`~shared.protocol.schema.ProtocolError` with its ``reason``. No Zenoh here.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shared.feature_sets import herakles_out_of_range

from . import limits as L
from .messages import ClassPosterior, ClockTick, DemoMarker, HumanKeypoints, HumanPose, OccupancyGrid, Plan, RobotState
from .schema import Message
from .schema import field_error as _err

__all__ = ["RobotSpec", "GridSpec", "Expectations", "check_values"]


def _numpy(x: Any) -> np.ndarray:
    x = x.detach().cpu().numpy() if hasattr(x, "detach") else x
    return np.asarray(x, dtype=np.float64)


@dataclass(frozen=True)
class RobotSpec:
    """The receiver's robot: its joints in order and their limits.

    Attributes:
        joint_names: The D joint names.
        lower, upper: ``(D,)`` position limits (rad or m).
        velocity: ``(D,)`` positive velocity limits (rad/s or m/s).
    """

    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray

    @classmethod
    def from_robot(cls, robot: Any) -> RobotSpec:
        """From a model with ``joint_names``, ``lower``, ``upper``, ``velocity_limits`` (torch or numpy)."""
        return cls(tuple(robot.joint_names), _numpy(robot.lower), _numpy(robot.upper),
                   _numpy(robot.velocity_limits))


@dataclass(frozen=True)
class GridSpec:
    """The receiver's scene grid: occupancy must cover exactly these bounds, at any allowed resolution.

    Attributes:
        lower: ``(3,)`` the grid's lower corner (the origin of voxel (0, 0, 0)), m.
        upper: ``(3,)`` its upper corner, m.
        min_resolution: The finest resolution the receiver takes (m; 0: any the wire allows). The planner builds
            lookup tables of every grid it gets, 8 corners a voxel: at 0.01 m a 283-byte message cost it 760 MB.
    """

    lower: np.ndarray
    upper: np.ndarray
    min_resolution: float = 0.0

    @classmethod
    def from_grid(cls, grid: Any, finest: float = 0.0) -> GridSpec:
        """From a ``shared.scene.Grid`` (``min``, ``max``); ``finest``: ``min_resolution``."""
        return cls(np.asarray(grid.min, dtype=np.float64), np.asarray(grid.max, dtype=np.float64), finest)

    @classmethod
    def planning(cls, grid: Any) -> GridSpec:
        """What the planner takes on the scene grid ``grid``: its bounds, no finer than half its resolution.

        8x the scene grid's voxels at most: the planner's lookup tables are the cost. The predictor checks its model's
        grid against it at start.
        """
        return cls.from_grid(grid, float(grid.resolution) / 2)

    def mismatch(self, origin: Any, dims: Any, resolution: float) -> tuple[str, str] | None:
        """Why a grid at ``origin`` ``(3,)`` of ``dims`` ``(3,)`` voxels of ``resolution`` m does not fit this one.

        Returns:
            ``(field, reason)``, or None when it fits.
        """
        origin = np.asarray(origin, dtype=np.float64)
        if resolution < self.min_resolution - 1e-9:
            return "resolution", f"{resolution:g} m is finer than the {self.min_resolution:g} m this receiver takes"
        if not np.allclose(origin, self.lower, rtol=0.0, atol=1e-6):
            return "origin", f"{origin.tolist()} is not the scene grid's {self.lower.tolist()}"
        want = self.dims_at(resolution)
        if tuple(int(d) for d in dims) != want:
            return "dims", (f"{[int(d) for d in dims]} at {resolution:g} m do not cover the scene grid "
                            f"{self.lower.tolist()}..{self.upper.tolist()} (expected {list(want)})")
        return None

    def dims_at(self, resolution: float) -> tuple[int, ...]:
        """The voxel counts of these bounds at ``resolution`` (as ``shared.scene.Grid.dims``)."""
        n = np.ceil((self.upper - self.lower) / resolution - 1e-9).astype(int)
        return tuple(int(v) for v in n)


@dataclass
class Expectations:
    """What a receiving service knows and checks messages against.

    Attributes:
        clock: ``"realtime"`` (wall-clock stamps, ``tick == -1``), ``"lockstep"`` (simulated stamps)
            or ``"auto"`` (by the message: ``tick == -1`` real time, else lock-step; tick -1 at stamp 0 is the
            lock-step state before step 0).
        period_s: The lock-step period P, when the receiver knows it (the executor).
        max_tick: Returns the highest tick that may arrive now (the executor: its clock + 1).
        robot: The receiver's robot, or None.
        grid: The receiver's scene grid, or None.
        n_classes: The number of motion classes the receiver expects, or None.
        now: Wall clock (s) for real-time stamps.
    """

    clock: str = "auto"
    period_s: float | None = None
    max_tick: Callable[[], int] | None = None
    robot: RobotSpec | None = None
    grid: GridSpec | None = None
    n_classes: int | None = None
    now: Callable[[], float] = field(default=time.time)

    def __post_init__(self) -> None:
        if self.clock not in ("realtime", "lockstep", "auto"):
            raise ValueError(f"Expectations.clock: 'realtime', 'lockstep' or 'auto', got {self.clock!r}")


def _stamp(msg: Any, exp: Expectations) -> None:
    t, tick, stamp = msg.TYPE, msg.tick, msg.stamp
    if not -1 <= tick <= L.MAX_TICK:
        raise _err(t, "tick", f"{tick} not in [-1, {L.MAX_TICK}]", "out-of-range")
    # auto: tick -1 is real time, except the lock-step state before step 0 (tick -1, stamp 0), which a receiver
    # that knows no clock refused as 56 years old
    before_step_0 = tick == -1 and 0.0 <= stamp <= L.LOGICAL_STAMP_TOL_S
    realtime = exp.clock == "realtime" or (exp.clock == "auto" and tick == -1 and not before_step_0)
    if realtime:
        if tick != -1:
            raise _err(t, "tick", f"{tick} in a real-time run (must be -1)", "mismatch")
        now = exp.now()
        if stamp > now + L.STAMP_FUTURE_S:
            raise _err(t, "stamp", f"{stamp:.3f} is {stamp - now:.3g} s in the future", "stamp-future")
        if stamp < now - L.STAMP_PAST_S:
            raise _err(t, "stamp", f"{stamp:.3f} is {now - stamp:.3g} s old (limit {L.STAMP_PAST_S:g} s)",
                       "stamp-past")
        return
    if exp.max_tick is not None and tick > exp.max_tick():
        raise _err(t, "tick", f"{tick} is ahead of the lock-step clock (at most {exp.max_tick()} now)",
                   "stamp-future")
    if not 0.0 <= stamp <= L.MAX_LOGICAL_STAMP_S:
        raise _err(t, "stamp", f"{stamp:.6g} is no simulated time (lock-step: 0 .. {L.MAX_LOGICAL_STAMP_S:g})",
                   "stamp-past" if stamp < 0 else "stamp-future")
    period = exp.period_s if exp.period_s else L.MAX_PERIOD_S
    lo = tick * period - L.LOGICAL_STAMP_TOL_S if exp.period_s else -math.inf
    hi = (tick + 1) * period + L.LOGICAL_STAMP_TOL_S
    if stamp > hi:
        raise _err(t, "stamp", f"{stamp:.6g} s is after tick {tick} (ends at {hi:.6g} s)", "stamp-future")
    if stamp < lo:
        raise _err(t, "stamp", f"{stamp:.6g} s is before tick {tick} (starts at {lo:.6g} s)", "stamp-past")


def _counter(t: str, name: str, value: int, low: int, high: int) -> None:
    if not low <= value <= high:
        raise _err(t, name, f"{value} not in [{low}, {high}]", "out-of-range")


def _joints(t: str, names: Sequence[str], q: np.ndarray, exp: Expectations, what: str) -> None:
    """``q (..., D)`` positions: the receiver's joints and limits (or the generic bound)."""
    robot = exp.robot
    if not np.isfinite(q).all():  # decode refuses these; a message built in this process is checked here only
        raise _err(t, what, "contains NaN or infinity", "non-finite")
    if robot is None:
        if q.size and float(np.max(np.abs(q))) > L.MAX_ABS_JOINT:
            raise _err(t, what, f"|q| up to {float(np.max(np.abs(q))):.4g} (limit {L.MAX_ABS_JOINT:g})",
                       "joint-limits")
        return
    if tuple(names) != robot.joint_names:
        raise _err(t, "joint_names", f"{list(names)[:8]} are not this robot's joints {list(robot.joint_names)}",
                   "mismatch")
    flat = q.reshape(-1, len(robot.joint_names))
    low, high = robot.lower - L.JOINT_LIMIT_TOL, robot.upper + L.JOINT_LIMIT_TOL
    bad = np.nonzero(np.any((flat < low) | (flat > high), axis=0))[0]
    if bad.size:
        j = int(bad[0])
        worst = flat[:, j][np.argmax(np.maximum(flat[:, j] - robot.upper[j], robot.lower[j] - flat[:, j]))]
        raise _err(t, what, f"{robot.joint_names[j]} = {worst:.6g} outside [{robot.lower[j]:.4g}, "
                   f"{robot.upper[j]:.4g}] (+/- {L.JOINT_LIMIT_TOL:g}); {bad.size} joint(s) out", "joint-limits")


def _velocity(t: str, qd: np.ndarray, exp: Expectations) -> None:
    robot = exp.robot
    limit = (robot.velocity * (1.0 + L.VELOCITY_LIMIT_TOL) + 1e-9 if robot is not None
             else np.full(qd.shape, L.MAX_ABS_JOINT_VELOCITY))
    over = np.nonzero(np.abs(qd) > limit)[0]
    if over.size:
        j = int(over[0])
        name = robot.joint_names[j] if robot is not None else str(j)
        raise _err(t, "qd", f"{name} velocity {qd[j]:.6g} above its limit {limit[j]:.4g}", "velocity")


def _pose(msg: HumanPose, exp: Expectations) -> None:
    _counter(msg.TYPE, "demo_id", msg.demo_id, 0, L.MAX_DEMO_ID)
    _counter(msg.TYPE, "index", msg.index, 0, L.MAX_SAMPLES)
    out = herakles_out_of_range(msg.features)
    if out:
        raise _err(msg.TYPE, "features", out, "out-of-range")


def _keypoints(msg: HumanKeypoints, exp: Expectations) -> None:
    # a sensor runs in real time: every sender stamps -1, and a receiver on clock "auto" took a tick >= 0 as lock-step
    if msg.tick != -1:
        raise _err(msg.TYPE, "tick", f"{msg.tick}: a sensor runs in real time (must be -1)", "mismatch")
    _counter(msg.TYPE, "frame", msg.frame, 0, L.MAX_FRAME)
    seen = msg.positions[~np.isnan(msg.positions).any(axis=1)]
    if seen.size and float(np.max(np.abs(seen))) > L.MAX_KEYPOINT_M:
        j = int(np.argmax(np.where(np.isnan(msg.positions), 0.0, np.abs(msg.positions)).max(axis=1)))
        raise _err(msg.TYPE, "positions", f"{msg.names[j]!r} at {msg.positions[j].round(3).tolist()} m, beyond "
                   f"{L.MAX_KEYPOINT_M:g} m of the sensor", "out-of-range")


def _marker(msg: DemoMarker, exp: Expectations) -> None:
    _counter(msg.TYPE, "demo_id", msg.demo_id, 0, L.MAX_DEMO_ID)
    _counter(msg.TYPE, "n_samples", msg.n_samples, 0, L.MAX_SAMPLES)
    _counter(msg.TYPE, "true_class", msg.true_class, -1, L.MAX_CLASSES - 1)


def _posterior(msg: ClassPosterior, exp: Expectations) -> None:
    _counter(msg.TYPE, "demo_id", msg.demo_id, 0, L.MAX_DEMO_ID)
    _counter(msg.TYPE, "index", msg.index, 0, L.MAX_SAMPLES)
    if np.any(msg.posterior > 1.0 + 1e-9):
        raise _err(msg.TYPE, "posterior", f"probability {float(msg.posterior.max()):.6g} above 1", "out-of-range")
    if not -1e9 <= msg.familiarity <= 1e6:  # nats per frame; the predictor floors it at -1e9 (novelty.SCORE_FLOOR)
        raise _err(msg.TYPE, "familiarity", f"{msg.familiarity:.6g} outside [-1e9, 1e6] nats per frame", "out-of-range")
    if exp.n_classes is not None and msg.posterior.shape[0] != exp.n_classes:
        raise _err(msg.TYPE, "posterior", f"{msg.posterior.shape[0]} classes, the receiver has {exp.n_classes}",
                   "mismatch")


def _occupancy(msg: OccupancyGrid, exp: Expectations) -> None:
    t = msg.TYPE
    _counter(t, "demo_id", msg.demo_id, 0, L.MAX_DEMO_ID)
    _counter(t, "index", msg.index, 0, L.MAX_SAMPLES)
    if not L.MIN_RESOLUTION_M <= msg.resolution <= L.MAX_RESOLUTION_M:
        raise _err(t, "resolution", f"{msg.resolution:.6g} m not in [{L.MIN_RESOLUTION_M:g}, "
                   f"{L.MAX_RESOLUTION_M:g}]", "out-of-range")
    if float(np.max(np.abs(msg.origin))) > L.MAX_COORDINATE_M:
        raise _err(t, "origin", f"{msg.origin.tolist()} beyond {L.MAX_COORDINATE_M:g} m", "out-of-range")
    # occupancy in [0, 1] holds by construction: values are uint8 q, p = q / 255
    wrong = exp.grid.mismatch(msg.origin, msg.dims, msg.resolution) if exp.grid is not None else None
    if wrong is not None:
        raise _err(t, wrong[0], wrong[1], "mismatch")


def _plan(msg: Plan, exp: Expectations) -> None:
    t = msg.TYPE
    _counter(t, "step", msg.step, 0, L.MAX_TICK)
    _counter(t, "occupancy_tick", msg.occupancy_tick, -1, L.MAX_TICK)
    _counter(t, "occupancy_index", msg.occupancy_index, -1, L.MAX_SAMPLES)
    if not L.MIN_DT_S <= msg.dt <= L.MAX_DT_S:
        raise _err(t, "dt", f"{msg.dt:.6g} s not in [{L.MIN_DT_S:g}, {L.MAX_DT_S:g}]", "out-of-range")
    if not 0.0 <= msg.planning_ms <= L.MAX_PLANNING_MS:
        raise _err(t, "planning_ms", f"{msg.planning_ms:.6g} not in [0, {L.MAX_PLANNING_MS:g}]", "out-of-range")
    for name in ("cost_smoothness", "cost_obstacle", "cost_human", "cost_total"):
        cost = getattr(msg, name)[msg.valid]
        if cost.size and float(np.max(np.abs(cost))) > L.MAX_ABS_COST:
            raise _err(t, name, f"|cost| {float(np.max(np.abs(cost))):.4g} above {L.MAX_ABS_COST:g}", "out-of-range")
        if cost.size and float(np.min(cost)) < 0.0:  # each term is a sum of squares or penetrations, never below 0
            raise _err(t, name, f"{float(np.min(cost)):.6g} is negative (every cost term is >= 0)", "out-of-range")
    # every goal's waypoints, an invalid goal's too: the live view and the log's scene run FK on all K
    _joints(t, msg.joint_names, msg.trajectories.astype(np.float64), exp, "trajectories")


def _state(msg: RobotState, exp: Expectations) -> None:
    _counter(msg.TYPE, "goal", msg.goal, -1, L.MAX_GOALS - 1)
    _joints(msg.TYPE, msg.joint_names, msg.q, exp, "q")
    _velocity(msg.TYPE, msg.qd, exp)


def _clock(msg: ClockTick, exp: Expectations) -> None:
    t = msg.TYPE
    if not L.MIN_PERIOD_S <= msg.period <= L.MAX_PERIOD_S:
        raise _err(t, "period", f"{msg.period:.6g} s not in [{L.MIN_PERIOD_S:g}, {L.MAX_PERIOD_S:g}]", "out-of-range")
    if exp.period_s and abs(msg.period - exp.period_s) > 1e-9 * exp.period_s:
        raise _err(t, "period", f"{msg.period:.6g} s, this run's period is {exp.period_s:.6g} s", "mismatch")
    if abs(msg.stamp - msg.tick * msg.period) > L.CLOCK_STAMP_RTOL * max(1.0, msg.stamp) + 1e-12:
        raise _err(t, "stamp", f"{msg.stamp:.9g} is not tick x period = {msg.tick * msg.period:.9g}", "stamp-past"
                   if msg.stamp < msg.tick * msg.period else "stamp-future")


_RULES: dict[type, Callable[[Any, Expectations], None]] = {
    HumanKeypoints: _keypoints, HumanPose: _pose, DemoMarker: _marker, ClassPosterior: _posterior,
    OccupancyGrid: _occupancy, Plan: _plan,
    RobotState: _state, ClockTick: _clock,
}


def check_values(msg: Message, exp: Expectations | None = None) -> None:
    """Check a decoded message's values against their meaning and the receiver's expectations.

    Args:
        msg: A message returned by :func:`~shared.protocol.codec.decode`.
        exp: What the receiver knows (default: nothing beyond the generic bounds, clock ``auto``).

    Raises:
        ProtocolError: With ``reason`` out-of-range, joint-limits, velocity, stamp-future,
            stamp-past or mismatch, and a text naming the field and the value.
    """
    exp = exp or Expectations()
    _stamp(msg, exp)
    _RULES[type(msg)](msg, exp)
