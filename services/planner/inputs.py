"""A replanning step's inputs checked: the robot configuration and the predicted occupancy grid.

Bad input raises :class:`PlannerInputError` with a one-line message naming the problem; the planner
then leaves its state unchanged and the service logs it and keeps serving.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from shared.protocol import OccupancyGrid
from shared.scene import Grid

__all__ = ["PlannerError", "PlannerInputError", "check_configuration", "check_lookahead", "check_occupancy"]


class PlannerError(ValueError):
    """The planner cannot plan (e.g. no reachable goal); the message says why."""


class PlannerInputError(PlannerError):
    """A replanning step's input (configuration, occupancy grid) is malformed; the message names it."""


def check_configuration(q: Any, lower: np.ndarray, upper: np.ndarray, limit_tol: float,
                        joint_names: Sequence[str] | None = None) -> np.ndarray:
    """Validate a robot configuration; returns it clamped into the limits.

    Args:
        q: ``(D,)`` the configuration (any array-like).
        lower: ``(D,)`` lower joint limits (float64).
        upper: ``(D,)`` upper joint limits (float64).
        limit_tol: How far outside the limits a value may lie and still be clamped rather than refused.
        joint_names: D names for the message (default: the indices).

    Returns:
        ``(D,)`` float64, within ``[lower, upper]``.

    Raises:
        PlannerInputError: Wrong shape, not finite, or more than ``limit_tol`` outside the limits.
    """
    d = lower.shape[0]
    try:
        arr = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError):
        raise PlannerInputError(f"robot configuration must be {d} numbers, got {q!r}") from None
    if arr.shape != (d,):
        raise PlannerInputError(f"robot configuration must have shape ({d},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise PlannerInputError(f"robot configuration contains NaN or inf: {arr.tolist()}")
    bad = np.nonzero((arr < lower - limit_tol) | (arr > upper + limit_tol))[0]
    if bad.size:
        names = joint_names or [str(i) for i in range(d)]
        what = ", ".join(f"{names[i]}={arr[i]:.4f} not in [{lower[i]:.4f}, {upper[i]:.4f}]" for i in bad)
        raise PlannerInputError(f"robot configuration outside the joint limits: {what}")
    return np.clip(arr, lower, upper)


def check_lookahead(lookahead_s: Any) -> float:
    """A step's lookahead (s), finite and >= 0.

    NaN raised an IndexError that stopped the service; inf started the plan at the goal, 2 rad from a robot that had
    not moved (a review).

    Raises:
        PlannerInputError: Not such a number.
    """
    value = float(lookahead_s)
    if not 0 <= value < math.inf:
        raise PlannerInputError(f"lookahead_s must be finite and >= 0, got {lookahead_s!r}")
    return value


def check_occupancy(occupancy: Any, grid: Grid) -> tuple[np.ndarray, np.ndarray, float]:
    """Validate an occupancy grid: an ``OccupancyGrid`` message or a dense ``(nx, ny, nz)`` array.

    Args:
        occupancy: The message, or a dense array of probabilities in [0, 1].
        grid: Geometry of a dense array.

    Returns:
        ``(occ (nx, ny, nz), origin (3,), resolution)``.

    Raises:
        PlannerInputError: Wrong shape or geometry (fewer than 2 voxels along an axis), NaN, values outside [0, 1].
    """
    if isinstance(occupancy, OccupancyGrid):
        try:
            occupancy.check()
        except ValueError as exc:
            raise PlannerInputError(f"occupancy grid: {exc}") from None
        dense, origin, res = occupancy.to_dense(), np.asarray(occupancy.origin, float), float(occupancy.resolution)
    else:
        try:
            dense = np.asarray(occupancy, dtype=np.float32)
        except (TypeError, ValueError):
            raise PlannerInputError("occupancy grid is not a numeric array") from None
        if dense.shape != tuple(grid.dims):
            raise PlannerInputError(f"occupancy grid has shape {dense.shape}, expected {tuple(grid.dims)} "
                                    f"for the grid {grid.min.tolist()}..{grid.max.tolist()} at {grid.resolution} m")
        origin, res = np.asarray(grid.origin, float), float(grid.resolution)
    if dense.ndim != 3:
        raise PlannerInputError(f"occupancy grid must be 3-D, got shape {dense.shape}")
    if min(dense.shape) < 2:
        raise PlannerInputError(f"occupancy grid has shape {dense.shape}: the planner's trilinear lookup needs at "
                                "least 2 voxels along each axis")
    if not np.all(np.isfinite(dense)):
        raise PlannerInputError(f"occupancy grid contains {int(np.sum(~np.isfinite(dense)))} NaN/inf values")
    if dense.size and (dense.min() < 0 or dense.max() > 1):
        raise PlannerInputError(f"occupancy values must be in [0, 1], got [{dense.min()}, {dense.max()}]")
    if not (math.isfinite(res) and res > 0) or not np.all(np.isfinite(origin)):
        raise PlannerInputError(f"occupancy grid geometry invalid: origin {origin}, resolution {res}")
    return dense, origin, res
