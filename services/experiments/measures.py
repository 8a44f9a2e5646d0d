"""What an executed robot trajectory did to the human: the paper's interference and the real clearance.

* :func:`interference` is the paper's Table I measure (section V.A, VI.B): the penetration cost of a
  configuration q is the sum of the predicted occupancy p(x|xi) over the voxels x that contain points
  sampled on the robot's structure; the measure integrates it over the executed trajectory (seconds),
  against one occupancy grid (the final, most accurate prediction).
  The points are the robot's collision spheres, sampled on their surfaces (and centres) at most half
  a voxel apart ("the sampling has to be dense enough not to miss any voxel", IV.D): a surface
  measure, like the paper's points on the robot's surface. A voxel wholly inside a sphere (not its
  centre's) is not counted, and one the surface only grazes can fall between the points (one sphere of
  0.17 m in 0.05 m voxels all at p = 1: 180 counted of the 294 it reaches into, 75 of them wholly
  inside). Each voxel counts once per configuration, however many points fall in it.
* :func:`body_clearance` (``shared.clearance``) measures against the human who was really there: the distance
  between the robot's collision spheres and the human model's body capsules, posed at the same instant.

Both are pure numpy/torch functions of logged data (configurations, stamps, grids, postures).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from scipy.ndimage import distance_transform_edt

from shared.protocol import OccupancyGrid

__all__ = ["sphere_surface_offsets", "robot_points", "penetration_per_state", "spheres_near_occupancy", "interference",
           "interference_over_time", "penetration", "path_samples", "interference_along_path",
           "ContactSummary",
           "postures_at", "contact_summary", "NEAR_M"]

NEAR_M = 0.05
"""Clearance (m) under which the robot counts as near the human (``time_near``)."""


def sphere_surface_offsets(radius: float, spacing: float) -> np.ndarray:
    """Points on a sphere of ``radius`` about the origin, at most about ``spacing`` apart, plus the centre.

    A Fibonacci lattice of ``n = max(6, ceil(4 pi r^2 / spacing^2))`` points: each covers a patch of
    area ``4 pi r^2 / n <= spacing^2``.

    Returns:
        ``(n + 1, 3)`` offsets (m); row 0 is the centre.
    """
    n = max(6, math.ceil(4 * math.pi * radius * radius / (spacing * spacing)))
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (3 - math.sqrt(5)) * i
    r = np.sqrt(np.clip(1 - z * z, 0, None))
    pts = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1) * radius
    return np.vstack([np.zeros((1, 3)), pts])


def _sphere_centres(robot: Any, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(N, S, 3)`` collision-sphere centres of ``q (N, D)`` and their ``(S,)`` radii (float64)."""
    qt = torch.as_tensor(np.asarray(q, dtype=np.float64), dtype=robot.lower.dtype, device=robot.lower.device)
    with torch.no_grad():
        centres = robot.sphere_centers(qt).double().cpu().numpy()
    return centres, robot.sphere_radii.double().cpu().numpy()


def robot_points(robot: Any, q: np.ndarray, spacing: float) -> np.ndarray:
    """Points sampled on the robot's structure (every collision sphere: centre and surface).

    Args:
        robot: Robot model with ``sphere_centers(q (N, D)) -> (N, S, 3)`` and ``sphere_radii (S,)`` (torch).
        q: ``(N, D)`` configurations.
        spacing: Largest distance between neighbouring surface points (m).

    Returns:
        ``(N, P, 3)`` world points (float64).
    """
    centres, radii = _sphere_centres(robot, q)
    offsets = [sphere_surface_offsets(float(r), spacing) for r in radii]
    owner = np.concatenate([np.full(len(o), s) for s, o in enumerate(offsets)])  # (P,)
    return centres[:, owner, :] + np.vstack(offsets)[None]


def _dense(occupancy: OccupancyGrid | np.ndarray) -> np.ndarray:
    return occupancy.to_dense(np.float64) if isinstance(occupancy, OccupancyGrid) else np.asarray(occupancy, float)


def _voxel_of(points: np.ndarray, origin: np.ndarray, resolution: float, dims: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """``(..., 3)`` voxel indices of ``points (..., 3)``, clipped into the grid; ``(...)`` whether each was inside."""
    idx = np.floor((points - origin) / resolution).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < dims), axis=-1)
    return np.clip(idx, 0, dims - 1), inside


def _voxel_sums(state: np.ndarray, points: np.ndarray, dense: np.ndarray, origin: np.ndarray, resolution: float,
                n_states: int) -> np.ndarray:
    """Per state, the sum of ``dense`` over the distinct voxels holding at least one of its points.

    Args:
        state: ``(M,)`` the state each point belongs to.
        points: ``(M, 3)`` world points.
        dense: ``(X, Y, Z)`` voxel values.
        origin: ``(3,)`` the grid's corner (m).
        resolution: Voxel edge (m).
        n_states: Number of states (the length of the result).

    Returns:
        ``(n_states,)`` sums (points outside the grid add nothing).
    """
    dims = np.asarray(dense.shape, dtype=np.int64)
    idx, inside = _voxel_of(points, origin, resolution, dims)
    flat = np.ravel_multi_index(tuple(idx.T), tuple(dims))
    values = dense.reshape(-1)
    hit = inside & (values[flat] > 0)  # voxels of zero probability add nothing: skip them before unique
    n_vox = int(np.prod(dims))
    keys = np.unique(state[hit].astype(np.int64) * n_vox + flat[hit])
    return np.bincount(keys // n_vox, weights=values[keys % n_vox], minlength=n_states)


def penetration_per_state(points: np.ndarray, occupancy: OccupancyGrid) -> np.ndarray:
    """The paper's penetration cost of each configuration: sum of p(x) over the voxels its points occupy.

    Args:
        points: ``(N, P, 3)`` robot points per configuration (:func:`robot_points`).
        occupancy: The occupancy grid (voxel probabilities in [0, 1]).

    Returns:
        ``(N,)`` sum over the distinct voxels containing at least one point (points outside the grid
        add nothing).
    """
    n, p = points.shape[:2]
    state = np.repeat(np.arange(n), p)
    return _voxel_sums(state, points.reshape(-1, 3), _dense(occupancy), np.asarray(occupancy.origin, np.float64),
                       float(occupancy.resolution), n)


def spheres_near_occupancy(centres: np.ndarray, radii: np.ndarray, occupancy: OccupancyGrid) -> np.ndarray:
    """Which spheres may put a point into a voxel of non-zero probability (a conservative test).

    A point ``p`` of a sphere ``(c, r)`` lies within ``r`` of ``c``, and any point lies within
    ``sqrt(3)/2`` voxel edges of its voxel's centre, so the sphere can reach a non-zero voxel only if
    the distance from ``c``'s voxel centre to the nearest non-zero voxel centre is at most
    ``r + sqrt(3) * resolution``. Spheres whose centre lies outside the grid are kept.

    Args:
        centres: ``(N, S, 3)`` sphere centres.
        radii: ``(S,)`` their radii.
        occupancy: The grid.

    Returns:
        ``(N, S)`` bool: False where the sphere certainly touches no non-zero voxel.
    """
    return _near(centres, radii, _dense(occupancy), np.asarray(occupancy.origin, np.float64),
                 float(occupancy.resolution))


def _near(centres: np.ndarray, radii: np.ndarray, dense: np.ndarray, origin: np.ndarray, res: float) -> np.ndarray:
    """:func:`spheres_near_occupancy` on the dense grid ``dense`` with corner ``origin`` and voxel edge ``res``."""
    if not np.any(dense > 0):
        return np.zeros(centres.shape[:2], dtype=bool)
    to_nonzero = distance_transform_edt(dense <= 0) * res  # (X, Y, Z) m between voxel centres
    ci, inside = _voxel_of(centres, origin, res, np.asarray(dense.shape, dtype=np.int64))
    reach = radii[None, :] + math.sqrt(3.0) * res + 1e-9
    return ~inside | (to_nonzero[ci[..., 0], ci[..., 1], ci[..., 2]] <= reach)


def penetration(robot: Any, q: np.ndarray, occupancy: OccupancyGrid, spacing: float | None = None) -> np.ndarray:
    """The paper's penetration cost of each configuration against one grid (:func:`penetration_per_state`).

    Only the spheres that can reach a non-zero voxel (:func:`spheres_near_occupancy`) are sampled:
    the others add nothing, so the value equals that of every point of :func:`robot_points`.

    Args:
        robot: Robot model (:func:`robot_points`).
        q: ``(N, D)`` configurations.
        occupancy: The grid to score against (the final prediction).
        spacing: Surface sampling of the robot's spheres (default: half the grid's voxel edge).

    Returns:
        ``(N,)`` probability-voxels: the sum of p(x) over the distinct voxels the configuration's points occupy.
    """
    q = np.asarray(q, dtype=np.float64)
    if len(q) == 0:
        return np.zeros(0)
    centres, radii = _sphere_centres(robot, q)
    dense, origin, res = _dense(occupancy), np.asarray(occupancy.origin, np.float64), float(occupancy.resolution)
    near = _near(centres, radii, dense, origin, res)  # (N, S)
    spacing = spacing or res / 2
    states, points = [np.zeros(0, np.int64)], [np.zeros((0, 3))]
    for s in np.flatnonzero(near.any(axis=0)):
        rows = np.flatnonzero(near[:, s])
        offsets = sphere_surface_offsets(float(radii[s]), spacing)  # (O, 3)
        states.append(np.repeat(rows, len(offsets)))
        points.append((centres[rows, s, None, :] + offsets[None]).reshape(-1, 3))
    return _voxel_sums(np.concatenate(states), np.concatenate(points), dense, origin, res, len(q))


def interference_over_time(robot: Any, q: np.ndarray, stamps: np.ndarray, occupancy: OccupancyGrid,
                           spacing: float | None = None) -> np.ndarray:
    """Each executed state's share of :func:`interference`: ``cost(q_n) * (t_n - t_{n-1})``, 0 for the first.

    Args:
        robot: Robot model (:func:`robot_points`).
        q: ``(N, D)`` executed configurations, in time order.
        stamps: ``(N,)`` their times (s).
        occupancy: The grid to score against (the final prediction).
        spacing: Surface sampling of the robot's spheres (default: half the grid's voxel edge).

    Returns:
        ``(N,)`` probability-voxels x seconds.
    """
    q = np.asarray(q, dtype=np.float64)
    if len(q) < 2:
        return np.zeros(len(q))
    cost = penetration(robot, q, occupancy, spacing)
    dt = np.clip(np.diff(np.asarray(stamps, dtype=np.float64)), 0.0, None)
    return np.concatenate([[0.0], cost[1:] * dt])


def path_samples(q: np.ndarray, ds: float, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Configurations every ``ds`` of configuration-space length along the polyline through ``q``.

    Args:
        q: ``(N, D)`` configurations, in order (the executed path).
        ds: Spacing (> 0) in the weighted joint-space Euclidean norm.
        weights: ``(D,)`` per-joint weights of the norm (None: 1 each).

    Returns:
        ``(samples (M, D), segment (M,))``: the configurations at lengths ``ds, 2 ds, ...`` up to the path's
        length, and for each the index n >= 1 of the state that ends its segment (``q[n-1] -> q[n]``).
    """
    q = np.asarray(q, dtype=np.float64)
    if not ds > 0:
        raise ValueError(f"path_samples: ds must be > 0, got {ds}")
    if len(q) < 2:
        return np.zeros((0, q.shape[-1] if q.ndim == 2 else 0)), np.zeros(0, np.int64)
    w = 1.0 if weights is None else np.asarray(weights, dtype=np.float64)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0) * w, axis=-1))])
    s = ds * np.arange(1, int(np.floor(cum[-1] / ds + 1e-9)) + 1)
    seg = np.clip(np.searchsorted(cum, s, side="left"), 1, len(q) - 1)  # q[seg-1] -> q[seg] holds length s
    span = cum[seg] - cum[seg - 1]
    a = np.where(span > 0, (s - cum[seg - 1]) / np.where(span > 0, span, 1.0), 1.0)[:, None]
    return (1.0 - a) * q[seg - 1] + a * q[seg], seg


def interference_along_path(robot: Any, q: np.ndarray, occupancy: OccupancyGrid, ds: float = 0.005,
                            spacing: float | None = None, weights: np.ndarray | None = None) -> np.ndarray:
    """Each executed state's share of the path-length integral of the penetration (the paper authors' measure).

    The executed path is sampled at its start and every ``ds`` of configuration-space length (:func:`path_samples`;
    the authors' code: every 0.005 of Move3D's path parameter, docs/experiments.md), and each step between two
    samples counts ``(c_prev + c) / 2 x ds`` of their penetrations (:func:`penetration`): the trapezoid of the
    authors' ``cs_integral`` (``deltaStepCost``). A path outside every occupied voxel scores 0, and the score grows
    with the length inside. Time plays no part: a robot standing still accrues nothing.

    Args:
        robot: Robot model (:func:`robot_points`).
        q: ``(N, D)`` executed configurations, in order.
        occupancy: The grid to score against (the final prediction).
        ds: Sampling step along the path.
        spacing: Surface sampling of the robot's spheres (default: half the grid's voxel edge).
        weights: ``(D,)`` per-joint weights of the length (:func:`path_samples`).

    Returns:
        ``(N,)`` probability-voxels x configuration-space length, per state (the steps ending in its segment;
        0 for the first).
    """
    samples, seg = path_samples(q, ds, weights)
    out = np.zeros(len(np.asarray(q)))
    if len(samples):
        c = penetration(robot, np.concatenate([np.asarray(q, dtype=np.float64)[:1], samples]), occupancy, spacing)
        np.add.at(out, seg, 0.5 * (c[:-1] + c[1:]) * ds)  # (was a right sum: the start none, the end a whole step)
    return out


def interference(robot: Any, q: np.ndarray, stamps: np.ndarray, occupancy: OccupancyGrid,
                 spacing: float | None = None) -> float:
    """Integral penetration cost of an executed trajectory against one grid (the paper's Table I).

    Same arguments as :func:`interference_over_time`.

    Returns:
        ``sum_{n >= 1} cost(q_n) * (t_n - t_{n-1})`` in probability-voxels x seconds (0 for N < 2).
    """
    return float(interference_over_time(robot, q, stamps, occupancy, spacing).sum())


@dataclass(frozen=True)
class ContactSummary:
    """How close an executed trajectory came to the real human.

    Attributes:
        min_clearance: Smallest clearance over the run (m; negative: overlap).
        time_in_contact: Seconds with clearance <= 0.
        time_near: Seconds with clearance <= :data:`NEAR_M`.
    """

    min_clearance: float
    time_in_contact: float
    time_near: float


def contact_summary(clearances: np.ndarray, stamps: np.ndarray, near: float = NEAR_M) -> ContactSummary:
    """Summarise per-instant clearances ``(N,)`` at ``stamps (N,)``; each instant counts ``t_n - t_{n-1}``."""
    c = np.asarray(clearances, dtype=np.float64)
    if len(c) == 0:
        return ContactSummary(math.inf, 0.0, 0.0)
    dt = np.concatenate([[0.0], np.clip(np.diff(np.asarray(stamps, dtype=np.float64)), 0.0, None)])
    return ContactSummary(float(c.min()), float(dt[c <= 0].sum()), float(dt[c <= near].sum()))


def postures_at(poses: list[Any], stamps: np.ndarray, scene: Any) -> np.ndarray:
    """The human's scene-frame posture at given times, from the poses a run streamed.

    Args:
        poses: The streamed ``HumanPose`` messages of one demonstration, in time order.
        stamps: ``(N,)`` times (s) in the poses' time base.
        scene: The scene the human is placed in (relative to the first pose, as the predictor does).

    Returns:
        ``(N, 12)`` postures, linearly interpolated between samples; before the first pose the first,
        after the last pose the last (the human holds still).
    """
    from shared.human import place_in_scene

    if not poses:
        raise ValueError("postures_at: the run streamed no human pose")
    feats = np.array([p.features for p in poses], dtype=np.float64)  # (M, 12)
    t = np.array([p.stamp for p in poses], dtype=np.float64)
    s = np.asarray(stamps, dtype=np.float64)
    out = np.stack([np.interp(s, t, feats[:, j]) for j in range(feats.shape[1])], axis=-1)
    return place_in_scene(out, feats[0], scene)
