"""Planning costs of section V of the paper: obstacle (signed EDT), human occupancy, smoothness.

* **obstacle**: for every moving collision sphere of the PR2, the CHOMP-style smooth penetration of
  the sphere's surface distance ``d = sdf(centre) - radius`` below the clearance margin ``eps``:
  ``0`` for ``d >= eps``, ``(eps - d)^2 / (2 eps)`` for ``0 <= d < eps``, ``eps / 2 - d`` for ``d < 0``;
  summed over spheres, plus the same penalty on each arm sphere's distance to its nearest body sphere
  (self-collision; margin ``self_clearance``).
* **human**: the paper's penetration cost, the sum of the predicted occupancy ``p(x|xi)`` at points
  sampled on the robot: the sphere centres (and optionally 6 more points per sphere at
  ``human_point_radius`` x radius along the world axes, averaged per sphere), read from the voxel grid
  trilinearly (smooth, default) or from the containing voxel (``human_interp = "nearest"``, as in the paper).
* **body** (real time, folded into the obstacle term): the same hinge on each arm-carried sphere's clearance to the
  person's body as last seen, below ``body_clearance``, linear within its inner half (:mod:`services.planner.body`,
  :meth:`StateCost.set_body`).
* **smoothness**: the sum of squared accelerations (finite differences) of a trajectory
  (:func:`acceleration_cost`, per waypoint).

:class:`StateCost` maps configurations ``q (K, R, T, D)`` to the weighted per-waypoint terms
``(K, R, T, 2)`` = (obstacle, human) that STOMP needs; the smoothness weight is ``CostConfig.w_smooth``.
It owns the occupancy: :meth:`StateCost.set_occupancy` builds the :class:`OccupancyTables` (the voxel
lookup tables and the torso lift tables) once per grid. ``StateCost.__call__`` is the reference
implementation; the planner runs the same cost through :class:`~services.planner.fused.FusedCost`. Both
read only public tables: the robot's ``ChainTables``/``SphereTables``, the field's ``VoxelTables`` and
``StateCost.occupancy``; ``tests/services/planner/test_fused.py`` keeps them equal.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from shared.robot import PR2
from shared.scene import Scene

from .body import BodyCapsules, body_clearances
from .config import CostConfig
from .sdf import GridLookupError, SignedDistanceField, VoxelTables

__all__ = ["CostConfig", "StateCost", "CostInputError", "LiftTables", "OccupancyTables", "hinge_sum", "path_dt",
           "waypoint_times", "acceleration_cost"]


class CostInputError(ValueError):
    """A cost input (occupancy grid, configuration batch) is malformed; the message names it."""


def hinge_sum(e: torch.Tensor, eps: float, dim: int = -1) -> torch.Tensor:
    """Sum over ``dim`` of CHOMP's smooth hinge of a signed surface distance ``d``, written in ``e = eps - d``.

    Per element: ``e - eps / 2`` (``e > eps``: penetration), ``e^2 / (2 eps)`` (``0 <= e <= eps``: inside the
    margin), 0 (``e < 0``: clear); continuous with a continuous slope. The one hinge of the obstacle and
    self-collision terms, in the reference path and in the fused kernel.

    Args:
        e: ``(...)`` margin violations ``eps - d`` (m), any shape.
        eps: The margin (> 0, m).
        dim: The axis summed over (e.g. the spheres).

    Returns:
        ``e``'s shape without ``dim``.
    """
    e = e.clamp(min=0)
    m = e.clamp(max=eps)
    return (m * m).sum(dim) * (0.5 / eps) + (e - m).sum(dim)


def acceleration_cost(q: torch.Tensor) -> torch.Tensor:
    """Squared joint accelerations (second finite differences) per waypoint: the smoothness term.

    Args:
        q: ``(..., T, D)`` trajectories, T >= 3.

    Returns:
        ``(..., T)``: ``|q[t+1] - 2 q[t] + q[t-1]|^2`` at interior waypoints, 0 at both ends; the sum over
        T is the trajectory's smoothness cost.

    Raises:
        CostInputError: Fewer than 3 waypoints.
    """
    if q.shape[-2] < 3:
        raise CostInputError(f"acceleration_cost needs at least 3 waypoints, got shape {tuple(q.shape)}")
    acc = q[..., 2:, :] - 2 * q[..., 1:-1, :] + q[..., :-2, :]
    return F.pad((acc * acc).sum(-1), (1, 1))


def path_dt(q: torch.Tensor, inv_vmax: torch.Tensor, min_dt: float = 0.0) -> torch.Tensor:
    """Seconds per waypoint of a trajectory as the executor runs it: one ``dt`` for the whole path.

    The slowest segment at the scaled velocity limits sets it (``max_t,j |q[t+1, j] - q[t, j]| / vmax_j``); the
    plan carries it, at least ``min_dt``, and the executor spends it on every segment.

    Args:
        q: ``(..., T, D)`` trajectories, T >= 2.
        inv_vmax: ``(D,)`` 1 / scaled velocity limits.
        min_dt: Smallest time between waypoints (s; the plan's floor, 0: none).

    Returns:
        ``(...,)`` seconds.
    """
    return ((q[..., 1:, :] - q[..., :-1, :]).abs() * inv_vmax).amax((-2, -1)).clamp_min(min_dt)


def waypoint_times(q: torch.Tensor, inv_vmax: torch.Tensor) -> torch.Tensor:
    """Time each waypoint stands for when the trajectory is executed: the path's one dt (:func:`path_dt`) per segment.

    Half of each adjacent segment's time: ``dt`` inside, ``dt / 2`` at both ends. The state costs weighted by it
    integrate over the time the robot spends along the path, bunched waypoints included (weighting each waypoint
    by its own segments at the velocity limits charged 0.21 s in a band the executed robot crossed in 1.06 s,
    docs/planner.md). Without the plan's ``min_dt`` floor: under it every path would cost the same time whatever
    its length, and a robot near its goal looped there (an integration run never reached it in 30 steps); the
    executor still runs such a path at ``min_dt`` per segment, its last few tenths of a second.

    Args:
        q: ``(..., T, D)`` trajectories, T >= 2.
        inv_vmax: ``(D,)`` 1 / scaled velocity limits.

    Returns:
        ``(..., T)`` seconds.
    """
    seg = path_dt(q, inv_vmax)[..., None].expand(*q.shape[:-2], q.shape[-2] - 1)  # (..., T-1)
    return 0.5 * (F.pad(seg, (0, 1)) + F.pad(seg, (1, 0)))


@dataclass(frozen=True)
class LiftTables:
    """Costs of the torso-carried spheres tabulated over the torso lift (those spheres move with ``q[..., 0]`` only).

    Entry i is at lift ``lo + i * step``, ``i < n``; between entries the costs are linear in the lift.

    Attributes:
        lo: Lowest lift (m).
        step: Lift step (m).
        n: Entries (>= 2).
        values: ``(4, n - 1)`` unweighted sums over the torso-carried spheres; column i is the interval from
            entry i to i + 1, rows: obstacle at i, obstacle at i + 1, human at i, human at i + 1.
    """

    lo: float
    step: float
    n: int
    values: torch.Tensor

    def interpolate(self, lift: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``lift`` ``(...)`` (m, clamped to the table) -> ``(obstacle (...), human (...))``."""
        u = ((lift - self.lo) / self.step).clamp(0, self.n - 1)
        i = torch.clamp(u.long(), max=self.n - 2)
        f = u - i
        v = self.values.index_select(1, i.reshape(-1)).view(4, *lift.shape)
        return v[0] + (v[1] - v[0]) * f, v[2] + (v[3] - v[2]) * f


@dataclass(frozen=True)
class OccupancyTables:
    """The predicted occupancy as the costs read it; :meth:`StateCost.set_occupancy` builds one per grid.

    Attributes:
        voxels: :class:`~services.planner.sdf.VoxelTables` of the occupancy zero-padded by one voxel
            (``(nx + 2, ny + 2, nz + 2)`` values: 0 beyond the grid), None when no occupancy is set.
        lift: The torso lift tables on this occupancy (human rows 0 without one); None when the cost
            evaluates every sphere directly (``torso_table_step = 0`` or spheres not ordered for it).
    """

    voxels: VoxelTables | None
    lift: LiftTables | None


class StateCost:
    """Per-waypoint obstacle and human costs of PR2 configurations (the reference implementation).

    Args:
        robot: The PR2 model (device and dtype are taken from it).
        sdf: Signed distance field of the static scene (built from ``scene`` when None).
        config: Weights and options.
        scene: Needed when ``sdf`` is None.

    Attributes:
        terms: ``("obstacle", "human")``, the order of the last axis of :meth:`__call__`.
        spheres: Slice of the spheres that are costed (those moving with q).
        radii: ``(S',)`` their radii.
        has_self: Whether the arm-vs-body self-collision term is on.
        occupancy: :class:`OccupancyTables`, replaced by :meth:`set_occupancy`.
        body: The person's body as last seen (:class:`~services.planner.body.BodyCapsules`), set by
            :meth:`set_body`; None: no body term.
    """

    terms = ("obstacle", "human")

    def __init__(self, robot: PR2, sdf: SignedDistanceField | None = None, config: CostConfig | None = None,
                 scene: Scene | None = None) -> None:
        self.config = config or CostConfig()
        self.config.validate()
        self.robot = robot
        self.device, self.dtype = robot.device, robot.dtype
        if sdf is None:
            if scene is None:
                raise ValueError("StateCost needs a scene or a SignedDistanceField")
            sdf = SignedDistanceField(scene, self.config.sdf_resolution, device=self.device, dtype=self.dtype)
        self.sdf = sdf
        self.spheres = robot.moving_slice
        self.radii = robot.sphere_radii[self.spheres]
        offs = [torch.zeros(3)]
        if self.config.human_points == 7:
            eye = torch.eye(3)
            offs += [eye[i] * s for i in range(3) for s in (1.0, -1.0)]
        self._offsets = (torch.stack(offs).to(self.device, self.dtype)[None, :, :]
                         * (self.radii[:, None, None] * self.config.human_point_radius))  # (S', P, 3)
        self._offsets[:, 0] = 0.0
        self.has_self = bool(self.config.self_clearance >= 0 and robot.arm_spheres.numel() > 0
                             and robot.body_spheres.numel() > 0)
        # Spheres carried by the torso alone (head, left arm, torso) depend on q[..., 0] only: their
        # obstacle and human costs are tabulated over the lift range and interpolated linearly.
        arm_c, torso_c = robot.arm_carried_slice, robot.torso_carried_slice
        self._arm_rel = slice(0, arm_c.stop - self.spheres.start)
        self._lift: LiftTables | None = None
        if (self.config.torso_table_step > 0 and arm_c.start == self.spheres.start
                and arm_c.stop == torso_c.start and torso_c.stop == self.spheres.stop):
            lo, hi = float(robot.lower[0]), float(robot.upper[0])
            n = max(int(np.ceil((hi - lo) / self.config.torso_table_step)) + 1, 2)
            q_tab = robot.lower.expand(n, -1).clone()
            q_tab[:, 0] = torch.linspace(lo, hi, n, device=self.device, dtype=self.dtype)
            self._tab_rel = slice(torso_c.start - self.spheres.start, torso_c.stop - self.spheres.start)
            self._tab_centers = robot.sphere_centers(q_tab)[:, torso_c]  # (n, St, 3)
            obstacle = self._obstacle_spheres(self._tab_centers, self._tab_rel)  # (n,)
            self._lift = LiftTables(lo, (hi - lo) / (n - 1), n, torch.stack([obstacle[:-1], obstacle[1:]]))
        self.occupancy = self._tables(None)
        self.body: BodyCapsules | None = None

    def _tables(self, voxels: VoxelTables | None) -> OccupancyTables:
        """The :class:`OccupancyTables` of ``voxels`` (the lift tables' human rows evaluated on it)."""
        lift = self._lift
        if lift is not None:
            human = (self._human_spheres(self._tab_centers, self._tab_rel, voxels) if voxels is not None
                     else torch.zeros(lift.n, device=self.device, dtype=self.dtype))
            rows = torch.cat([lift.values[:2], torch.stack([human[:-1], human[1:]])]).contiguous()  # (4, n - 1)
            lift = dataclasses.replace(lift, values=rows)
        return OccupancyTables(voxels, lift)

    def _obstacle_spheres(self, c: torch.Tensor, rel: slice) -> torch.Tensor:
        """Static-obstacle hinge of spheres ``c`` ``(..., s, 3)`` (``rel``: their slice of the costed spheres)."""
        return hinge_sum(self.config.clearance + self.radii[rel] - self.sdf(c), self.config.clearance)

    def _human_spheres(self, c: torch.Tensor, rel: slice, voxels: VoxelTables) -> torch.Tensor:
        """Summed occupancy ``voxels`` at spheres ``c`` ``(..., s, 3)``."""
        pts = c.unsqueeze(-2) + self._offsets[rel] if self.config.human_points > 1 else c
        p = voxels.lookup(pts, self.config.human_interp)
        if self.config.human_points > 1:
            p = p.mean(-1)
        return p.sum(-1)

    def _self_term(self, centers: torch.Tensor) -> torch.Tensor:
        ds = self.robot.self_collision_distance(centers).amin(-1)  # (..., A) nearest body sphere per arm sphere
        eps = max(self.config.self_clearance, 1e-6)
        return hinge_sum(eps - ds, eps)

    @classmethod
    def from_scene(cls, scene: Scene, robot: PR2, config: CostConfig | None = None) -> StateCost:
        """The cost of ``scene``'s static obstacles for ``robot``."""
        return cls(robot, None, config, scene)

    def set_occupancy(self, occupancy: Any, origin: Any, resolution: float) -> None:
        """Set the predicted human occupancy X used by the human term.

        Args:
            occupancy: ``(nx, ny, nz)`` probabilities in [0, 1] (tensor or array); None clears it.
            origin: ``(3,)`` lower corner of voxel (0, 0, 0) (m).
            resolution: Voxel edge (m).

        Raises:
            CostInputError: Wrong rank, fewer than 2 voxels along an axis, NaN/inf, values outside [0, 1]
                (beyond 1e-4), or a bad origin/resolution.
        """
        if occupancy is None:
            self.occupancy = self._tables(None)
            return
        occ = torch.as_tensor(np.asarray(occupancy) if not torch.is_tensor(occupancy) else occupancy)
        occ = occ.to(self.device, self.dtype)
        if occ.ndim != 3:
            raise CostInputError(f"occupancy must be (nx, ny, nz), got shape {tuple(occ.shape)}")
        if not bool(torch.isfinite(occ).all()):
            raise CostInputError("occupancy contains NaN or inf")
        if occ.numel() and (float(occ.min()) < -1e-4 or float(occ.max()) > 1 + 1e-4):
            raise CostInputError(f"occupancy values must lie in [0, 1], got [{float(occ.min()):.4g}, "
                                 f"{float(occ.max()):.4g}]")
        try:
            voxels = VoxelTables.from_grid(occ.clamp(0, 1), origin, resolution, "zeros", "occupancy")
        except GridLookupError as exc:
            raise CostInputError(str(exc)) from None
        self.occupancy = self._tables(voxels)

    def set_body(self, ends: Any, radii: Any) -> None:
        """Set the person's body for the body term (``config.body_clearance`` > 0; real time).

        Args:
            ends: ``(C, 2, 3)`` capsule end points in the scene frame (m); None clears the body.
            radii: ``(C,)`` capsule radii (m).

        Raises:
            CostInputError: Wrong shapes or a value that is not finite.
        """
        if ends is None:
            self.body = None
            return
        try:
            self.body = BodyCapsules.build(ends, radii, self.device, self.dtype)
        except ValueError as exc:
            raise CostInputError(str(exc)) from None

    def _body_term(self, arm: torch.Tensor) -> torch.Tensor | None:
        """The body hinge of the arm-carried spheres ``arm`` ``(..., A, 3)`` (None: no body, or the term off)."""
        eps = self.config.body_clearance
        if self.body is None or eps <= 0:
            return None
        radii = self.robot.sphere_radii[self.robot.arm_carried_slice]
        gap = body_clearances(arm.movedim(-1, 0).movedim(-1, 1), radii, self.body)  # (A, ...)
        return hinge_sum(eps - gap, eps / 2, 0)

    def obstacle(self, centers: torch.Tensor) -> torch.Tensor:
        """Unweighted obstacle term, every sphere evaluated directly: ``centers`` ``(..., S, 3)`` -> ``(...)``."""
        cost = self._obstacle_spheres(centers[..., self.spheres, :], slice(None))
        if self.has_self:
            cost = cost + self._self_term(centers)
        return cost

    def human(self, centers: torch.Tensor) -> torch.Tensor:
        """Unweighted human term, every sphere evaluated directly.

        ``centers`` ``(..., S, 3)`` -> ``(...)`` summed occupancy (0 when no occupancy is set).
        """
        voxels = self.occupancy.voxels
        if voxels is None:
            return torch.zeros(centers.shape[:-2], device=centers.device, dtype=centers.dtype)
        return self._human_spheres(centers[..., self.spheres, :], slice(None), voxels)

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        """Weighted per-waypoint terms.

        Spheres carried by the arm joints are evaluated at their centres; spheres carried by the torso
        alone come from the lift tables (``torso_table_step``; equal to :meth:`obstacle` / :meth:`human`
        up to the linear interpolation in the lift). With a body set, the obstacle term includes the body term
        of the arm-carried spheres.

        Args:
            q: ``(K, R, T, D)`` configurations (any leading shape works).

        Returns:
            ``(K, R, T, 2)``: ``w_obstacle`` x obstacle and ``w_human`` x human, in ``terms`` order.
        """
        centers = self.robot.sphere_centers(q)
        tables = self.occupancy
        body = self._body_term(centers[..., self.robot.arm_carried_slice, :])
        if tables.lift is None:
            obstacle, human = self.obstacle(centers), self.human(centers)
        else:
            tab_obstacle, tab_human = tables.lift.interpolate(q[..., 0])
            arm = centers[..., self.robot.arm_carried_slice, :]
            obstacle = self._obstacle_spheres(arm, self._arm_rel) + tab_obstacle
            if self.has_self:
                obstacle = obstacle + self._self_term(centers)
            if tables.voxels is None:
                human = torch.zeros_like(obstacle)
            else:
                human = self._human_spheres(arm, self._arm_rel, tables.voxels) + tab_human
        if body is not None:
            obstacle = obstacle + body
        return torch.stack([self.config.w_obstacle * obstacle, self.config.w_human * human], dim=-1)

    def collision_free(self, q: torch.Tensor, margin: float = 0.0) -> torch.Tensor:
        """Collision check: ``q`` ``(..., D)`` -> ``(...)`` bool.

        True where every moving sphere is at least ``margin`` from the static obstacles and no arm
        sphere overlaps a body sphere.
        """
        centers = self.robot.sphere_centers(q)
        ok = ((self.sdf(centers[..., self.spheres, :]) - self.radii) >= margin).all(-1)
        if self.has_self:
            ok = ok & (self.robot.self_collision_distance(centers) >= 0).flatten(-2).all(-1)
        return ok

    def clearance(self, q: torch.Tensor) -> torch.Tensor:
        """``q`` ``(..., D)`` -> ``(...)`` smallest sphere surface distance to the static obstacles (m)."""
        centers = self.robot.sphere_centers(q)
        return (self.sdf(centers[..., self.spheres, :]) - self.radii).amin(-1)
