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
* **smoothness**: the sum of squared accelerations (finite differences) of a trajectory.

:class:`StateCost` maps configurations ``q (K, R, T, D)`` to the weighted per-waypoint terms
``(K, R, T, 2)`` = (obstacle, human) that STOMP needs; the smoothness weight is ``CostConfig.w_smooth``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from shared.robot import PR2
from shared.scene import Scene

from .sdf import GridLookupError, SignedDistanceField, _Lookup

__all__ = ["CostConfig", "StateCost", "CostInputError", "smoothness_cost", "smooth_penetration"]


class CostInputError(ValueError):
    """A cost input (occupancy grid, configuration batch) is malformed; the message names it."""


@dataclass
class CostConfig:
    """Weights and shape of the planning costs (held by :class:`StateCost` as ``config``)."""

    w_smooth: float = 10.0  # weight of the squared accelerations (rad^2 per waypoint step); the planner's default
    w_obstacle: float = 10.0  # weight of the obstacle penetration (m, summed over spheres)
    w_human: float = 1.0  # weight of the summed occupancy probability
    clearance: float = 0.05  # obstacle margin eps (m): spheres closer than this to a surface pay
    self_clearance: float = 0.01  # margin of the arm-vs-body self-collision term (m); < 0 disables it
    sdf_resolution: float = 0.02  # voxel edge of the static signed distance field (m)
    human_points: int = 1  # points per sphere for the human cost: 1 (centre) or 7 (centre + 6)
    human_point_radius: float = 0.7  # offset of the extra points, as a fraction of the sphere radius
    human_interp: str = "trilinear"  # "trilinear" or "nearest" (the voxel containing the point)
    torso_table_step: float = 0.002  # lift step (m) of the tabulated costs of torso-carried spheres; 0: off

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad value."""
        checks = [("w_smooth", self.w_smooth >= 0), ("w_obstacle", self.w_obstacle >= 0),
                  ("w_human", self.w_human >= 0), ("clearance", self.clearance > 0),
                  ("sdf_resolution", self.sdf_resolution > 0), ("human_points", self.human_points in (1, 7)),
                  ("human_point_radius", 0 <= self.human_point_radius <= 1),
                  ("human_interp", self.human_interp in ("trilinear", "nearest")),
                  ("torso_table_step", self.torso_table_step >= 0)]
        for name, ok in checks:
            if not ok:
                raise ValueError(f"costs.{name}: bad value {getattr(self, name)!r}")


def smooth_penetration(d: torch.Tensor, eps: float) -> torch.Tensor:
    """CHOMP's smooth hinge of a signed surface distance ``d`` (any shape) with margin ``eps`` > 0."""
    h = torch.clamp(eps - d, min=0)
    return torch.where(d < 0, eps / 2 - d, h * h * (0.5 / eps))


def smoothness_cost(q: torch.Tensor) -> torch.Tensor:
    """Sum of squared accelerations (second finite differences) of trajectories.

    Args:
        q: ``(..., T, D)`` trajectories, T >= 3.

    Returns:
        ``(...)`` ``sum_t sum_d (q[t+1] - 2 q[t] + q[t-1])^2``.
    """
    if q.shape[-2] < 3:
        raise CostInputError(f"smoothness_cost needs at least 3 waypoints, got shape {tuple(q.shape)}")
    acc = q[..., 2:, :] - 2 * q[..., 1:-1, :] + q[..., :-2, :]
    return (acc * acc).sum(dim=(-1, -2))


class StateCost:
    """Per-waypoint obstacle and human costs of PR2 configurations.

    Args:
        robot: The PR2 model (device and dtype are taken from it).
        sdf: Signed distance field of the static scene (built from ``scene`` when None).
        config: Weights and options.
        scene: Needed when ``sdf`` is None.

    Attributes:
        terms: ``("obstacle", "human")``, the order of the last axis of :meth:`__call__`.
        spheres: Slice of the spheres that are costed (those moving with q).
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
        self._occ: _Lookup | None = None
        self.has_self = bool(self.config.self_clearance >= 0 and robot.arm_spheres.numel() > 0
                             and robot.body_spheres.numel() > 0)
        # Spheres carried by the torso alone (head, left arm, torso) depend on q[..., 0] only: their
        # obstacle and human costs are tabulated over the lift range and interpolated linearly.
        arm_c, torso_c = robot.arm_carried_slice, robot.torso_carried_slice
        self._use_table = (self.config.torso_table_step > 0 and arm_c.start == self.spheres.start
                           and arm_c.stop == torso_c.start and torso_c.stop == self.spheres.stop)
        if self._use_table:
            lo, hi = float(robot.lower[0]), float(robot.upper[0])
            n = max(int(np.ceil((hi - lo) / self.config.torso_table_step)) + 1, 2)
            self._lift_lo, self._lift_step, self._lift_n = lo, (hi - lo) / (n - 1), n
            q_tab = robot.lower.expand(n, -1).clone()
            q_tab[:, 0] = torch.linspace(lo, hi, n, device=self.device, dtype=self.dtype)
            rel = slice(torso_c.start - self.spheres.start, torso_c.stop - self.spheres.start)
            self._tab_rel = rel
            self._tab_centers = robot.sphere_centers(q_tab)[:, torso_c]  # (n, St, 3)
            self._arm_rel = slice(0, arm_c.stop - self.spheres.start)
            self._tab_obstacle = self._pack(self._obstacle_spheres(self._tab_centers, rel))
            self._tab_human = self._pack(torch.zeros(n, device=self.device, dtype=self.dtype))

    @staticmethod
    def _pack(values: torch.Tensor) -> torch.Tensor:
        """``(n,)`` table -> ``(n - 1, 2)`` (value, next value) rows for one index_select per lookup."""
        return torch.stack([values[:-1], values[1:]], dim=-1).contiguous()

    def _table(self, packed: torch.Tensor, lift: torch.Tensor) -> torch.Tensor:
        """Linear interpolation of a packed lift table at ``lift`` ``(...)`` -> ``(...)``."""
        u = ((lift - self._lift_lo) / self._lift_step).clamp(0, self._lift_n - 1)
        i = torch.clamp(u.long(), max=self._lift_n - 2)
        f = u - i
        v = packed.index_select(0, i.reshape(-1)).reshape(*lift.shape, 2)
        return v[..., 0] + (v[..., 1] - v[..., 0]) * f

    def _obstacle_spheres(self, c: torch.Tensor, rel: slice) -> torch.Tensor:
        """Static-obstacle hinge of spheres ``c`` ``(..., s, 3)`` (``rel``: their slice of the costed spheres)."""
        return smooth_penetration(self.sdf(c) - self.radii[rel], self.config.clearance).sum(-1)

    def _human_spheres(self, c: torch.Tensor, rel: slice) -> torch.Tensor:
        """Summed occupancy at spheres ``c`` ``(..., s, 3)``."""
        assert self._occ is not None
        pts = c.unsqueeze(-2) + self._offsets[rel] if self.config.human_points > 1 else c
        p = self._occ(pts, self.config.human_interp)
        if self.config.human_points > 1:
            p = p.mean(-1)
        return p.sum(-1)

    def _self_term(self, centers: torch.Tensor) -> torch.Tensor:
        ds = self.robot.self_collision_distance(centers).amin(-1)  # (..., A) nearest body sphere per arm sphere
        return smooth_penetration(ds, max(self.config.self_clearance, 1e-6)).sum(-1)

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
            self._occ = None
            if self._use_table:
                self._tab_human = self._pack(torch.zeros(self._lift_n, device=self.device, dtype=self.dtype))
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
            self._occ = _Lookup(occ.clamp(0, 1), origin, resolution, "zeros", "occupancy")
        except GridLookupError as exc:
            raise CostInputError(str(exc)) from None
        if self._use_table:
            self._tab_human = self._pack(self._human_spheres(self._tab_centers, self._tab_rel))

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
        if self._occ is None:
            return torch.zeros(centers.shape[:-2], device=centers.device, dtype=centers.dtype)
        return self._human_spheres(centers[..., self.spheres, :], slice(None))

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        """Weighted per-waypoint terms.

        Spheres carried by the arm joints are evaluated at their centres; spheres carried by the torso
        alone come from the lift tables (``torso_table_step``; equal to :meth:`obstacle` / :meth:`human`
        up to the linear interpolation in the lift).

        Args:
            q: ``(K, R, T, D)`` configurations (any leading shape works).

        Returns:
            ``(K, R, T, 2)``: ``w_obstacle`` x obstacle and ``w_human`` x human, in ``terms`` order.
        """
        centers = self.robot.sphere_centers(q)
        if not self._use_table:
            obstacle, human = self.obstacle(centers), self.human(centers)
        else:
            lift = q[..., 0]
            arm = centers[..., self.robot.arm_carried_slice, :]
            obstacle = self._obstacle_spheres(arm, self._arm_rel) + self._table(self._tab_obstacle, lift)
            if self.has_self:
                obstacle = obstacle + self._self_term(centers)
            if self._occ is None:
                human = torch.zeros_like(obstacle)
            else:
                human = self._human_spheres(arm, self._arm_rel) + self._table(self._tab_human, lift)
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
