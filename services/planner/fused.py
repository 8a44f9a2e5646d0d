"""The planner's per-waypoint cost as one fused kernel: the same numbers as the reference path, fewer ops.

The reference is :meth:`Planner.waypoint_cost_reference` = ``StateCost`` (sphere FK, signed distance
field, occupancy, arm/body self-collision, torso lift tables) x waypoint time + ``w_smooth`` x squared
accelerations. :class:`FusedCost` computes exactly those terms for a ``(K, R, T, D)`` batch with a
handful of large tensor ops (each eager torch op costs 5-20 us on this CPU, so op count matters as much
as FLOPs), and can be ``torch.compile``-d:

* **FK**: every joint's local transform is ``A0 + cos(q) A1 + sin(q) A2 + q A3`` (base folded into the
  torso joint), built for all joints in one ``baddbmm``; the chain is 3 broadcast multiply-adds per
  joint on a batch-last ``(3, 4, B)`` layout; the arm-carried sphere centres are one matmul with a
  ``(S, 7 x 4)`` table (compiled: each sphere from its own link's 3 x 4 entries, which inductor fuses;
  the table is 6/7 zeros). Only the spheres that move with the arm joints are evaluated: the
  torso-carried ones come from ``StateCost``'s lift tables, the base's never move.
* **Lookups**: trilinear, from the corner-major packed cells ``(8, cells)`` of
  :class:`~services.planner.sdf.VoxelTables` (one gather per grid, 3 linear blends); the occupancy
  tables are the ones ``StateCost.set_occupancy`` built (read at every call); the static field is
  **cropped** to the cells where a sphere can pay anything (field value below ``clearance`` + the
  largest arm sphere radius, plus one layer): outside the crop both the
  reference and the crop give a zero hinge, inside they read the same corner values (tested).
* **Self-collision**: the body spheres are rigid in the base frame up to the torso lift ``l``, so
  ``|x - c_b - l v_b|^2`` is one ``(B_body, 7) x (7, A x B)`` matmul of features
  ``[x, l (x . v), 1, l, l^2]`` plus ``|x|^2`` (exact, every arm/body pair, as the reference).
* **Body** (real time): the arm-carried spheres' :func:`~services.planner.body.body_clearances`, hinged into the
  obstacle term; with no body set the capsules lie ``FAR_M`` away (the term exactly 0, the compiled shapes kept).
* time weights (``costs.waypoint_times``) and accelerations on ``(N, T, D)``; the hinge and the accelerations are
  ``costs.hinge_sum`` and ``costs.acceleration_cost``, as in the reference.

Everything is read from public tables: ``PR2.kinematics`` / ``PR2.spheres``, ``SignedDistanceField.tables``
and ``StateCost.occupancy``.

Tested equal to the reference to 1e-4 relative in float32 and about 1e-9 in float64
(``tests/services/planner/test_fused.py``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import torch

from shared.human import HumanModel
from shared.robot import PR2
from shared.scene import Grid

from .body import BodyCapsules, body_clearances
from .compiling import compile_every_shape
from .costs import StateCost, acceleration_cost, hinge_sum, waypoint_times
from .sdf import VoxelTables, crop_volume

__all__ = ["FusedCost", "supports"]

log = logging.getLogger("foresight.planner")


def supports(robot: Any, cost: Any) -> bool:
    """Whether :class:`FusedCost` reproduces ``cost`` for ``robot``.

    That is a PR2 ``StateCost`` with lift tables, one point per sphere and trilinear occupancy; otherwise
    the planner keeps the reference path.
    """
    if not isinstance(robot, PR2) or not isinstance(cost, StateCost) or cost.robot is not robot:
        return False
    c = cost.config
    arm = robot.arm_carried_slice
    anchors = robot.sphere_anchor[arm].tolist()
    return (cost.occupancy.lift is not None and c.human_points == 1 and c.human_interp == "trilinear"
            and bool(anchors) and min(anchors) >= 2 and max(anchors) <= len(robot.link_names) - 2
            and robot.arm_slice.start >= arm.start and robot.arm_slice.stop <= arm.stop)


def _cell_args(t: VoxelTables, flat: bool) -> tuple[torch.Tensor, ...]:
    """The lookup arguments of :func:`_trilinear` from ``t``: the packed cells, or the flat volume (compiled)."""
    if flat:
        return t.volume.view(-1), t.first, t.u_max, t.cell_max, t.voxel_strides, t.corner_offsets
    return t.cells, t.first, t.u_max, t.cell_max, t.cell_strides, t.corner_offsets


def _trilinear(p: torch.Tensor, inv_res: float, packed: torch.Tensor, first: torch.Tensor, u_max: torch.Tensor,
               cell_max: torch.Tensor, strides: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup, border-clamped (the arguments come from :func:`_cell_args`).

    Args:
        p: ``(3, S, B)`` points (coordinate-major).
        inv_res: 1 / voxel edge.
        packed: ``(8, cells)`` corner values (``VoxelTables.cells``; corner-major beat ``(cells, 8)`` rows by
            2x eager and compiled), or the ``(voxels,)`` volume itself (compiled: 8x smaller, stays in cache).
        first: ``(3,)`` centre of voxel 0.
        u_max: ``(3,)`` last voxel index (float).
        cell_max: ``(3,)`` last cell index (float).
        strides: ``(3,)`` cell strides, or voxel strides with a flat volume (float).
        offsets: ``(8,)`` flat offsets of a cell's 8 corners (flat volume only).

    Returns:
        ``(S, B)`` values.
    """
    u = torch.minimum(((p - first.view(3, 1, 1)) * inv_res).clamp(min=0), u_max.view(3, 1, 1))
    i0 = torch.minimum(u.floor(), cell_max.view(3, 1, 1))
    f = u - i0
    idx = (i0 * strides.view(3, 1, 1)).sum(0).long()  # (S, B)
    if packed.dim() == 1:
        # in range by construction (u clamped to [0, u_max], i0 <= cell_max): no wrap-around or bounds check,
        # which inductor would otherwise emit per gathered lane (-15% of the compiled kernel's time)
        c = torch.ops.aten._unsafe_index(packed, [idx.reshape(1, -1) + offsets.view(8, 1)]).view(2, 2, 2, -1)
    else:
        c = packed.index_select(1, idx.reshape(-1)).view(2, 2, 2, -1)
    fx, fy, fz = f.reshape(3, 1, -1)
    c = c[:, :, 0] + fz * (c[:, :, 1] - c[:, :, 0])  # a + w (b - a): torch.lerp's two-sided form costs a select
    c = c[:, 0] + fy * (c[:, 1] - c[:, 0])
    return (c[0] + fx[0] * (c[1] - c[0])).view(idx.shape)


def _kernel(q: torch.Tensor, a0: torch.Tensor, a123t: torch.Tensor, wt: torch.Tensor, sph_link: torch.Tensor,  # noqa: D417
            sph_local: torch.Tensor, obs_thr: torch.Tensor,
            sdf_packed: torch.Tensor, sdf_first: torch.Tensor, sdf_umax: torch.Tensor, sdf_cmax: torch.Tensor,
            sdf_strides: torch.Tensor, sdf_offs: torch.Tensor, sdf_lo: torch.Tensor, sdf_hi: torch.Tensor,
            occ_packed: torch.Tensor, occ_first: torch.Tensor, occ_umax: torch.Tensor, occ_cmax: torch.Tensor,
            occ_strides: torch.Tensor, occ_offs: torch.Tensor, tab: torch.Tensor, psi: torch.Tensor, v: torch.Tensor,
            r_arm: torch.Tensor, inv_vmax: torch.Tensor, body_ends: torch.Tensor, body_radii: torch.Tensor,
            r_carried: torch.Tensor, *, s: dict[str, Any]) -> torch.Tensor:
    """Fused per-waypoint cost terms (tensor arguments are constants prepared by :class:`FusedCost`).

    Args:
        q: ``(N, T, D)`` trajectories.
        a0, a123t: ``(D, 16, 1)``, ``(D, 16, 3)`` local transform basis (``ChainTables.transform_basis``).
        wt: ``(S, 28)`` homogeneous local centres of the S arm-carried spheres in the 7 arm links' blocks.
        sph_link, sph_local: ``(S,)`` the arm link (0-6) carrying each sphere, ``(S, 4, 1)`` its homogeneous
            local centre: the same centres without the zero blocks of ``wt`` (``s["pointwise"]``).
        obs_thr: ``(S, 1)`` ``clearance + radius``.
        sdf_*: cropped static field cells; ``sdf_lo``/``sdf_hi`` ``(3, 1, 1)`` the field's grid box.
        occ_*: occupancy cells (zero-padded).
        tab: ``(4, n - 1)`` ``LiftTables.values`` (obstacle, next, human, next) of the torso-carried spheres.
        psi: ``(B_body, 7)`` self-collision coefficients; v: ``(3, 1)`` world torso axis.
        r_arm: ``(A, 1)`` radii of the arm-group spheres.
        inv_vmax: ``(D,)`` 1 / scaled velocity limits.
        body_ends, body_radii: ``(C, 2, 3)``, ``(C,)`` the person's capsules (read with ``s["body"]``).
        r_carried: ``(S,)`` radii of the arm-carried spheres.
        s: Static scalars (inverse resolutions, margins, weights, slices, flags).

    Returns:
        ``(3, N, T)``: smoothness, obstacle, human per waypoint (weighted; with ``integrate`` the state terms
        times the waypoint time, the human's at the last waypoint plus ``dwell`` seconds).
    """
    n, t, d = q.shape
    b = n * t
    qt = q.reshape(b, d).t()  # (D, B)
    # one batched product (as pointwise ops, inductor recomputes them in every chain step: a K=2 call took 0.96 ms)
    h = torch.baddbmm(a0, a123t, torch.stack([torch.cos(qt), torch.sin(qt), qt], 1)).view(d, 4, 4, b)
    m = h[0, :3]
    links = []
    for j in range(1, d):
        hj = h[j]
        nm = m[:, 0:1] * hj[0]
        nm = torch.addcmul(nm, m[:, 1:2], hj[1])
        nm = torch.addcmul(nm, m[:, 2:3], hj[2])
        nm[:, 3] += m[:, 3]
        m = nm
        links.append(m)
    if s["pointwise"]:  # compiled: each sphere from its own link's 12 entries (no (S, 28) product, 6/7 zeros)
        p = (torch.stack(links, 1)[:, sph_link] * sph_local).sum(2)  # (3, S, B)
    else:
        p = torch.matmul(wt, torch.stack(links, 1).view(3, 4 * (d - 1), b))  # (3, S, B)
    # static obstacles (cropped field; the grid-box extension only where the crop reaches the grid's border)
    sdf = _trilinear(p, s["sdf_inv"], sdf_packed, sdf_first, sdf_umax, sdf_cmax, sdf_strides, sdf_offs)
    if s["sdf_extend"]:
        out = p - torch.minimum(torch.maximum(p, sdf_lo), sdf_hi)
        sdf = sdf + (out * out).sum(0).sqrt()
    obstacle = hinge_sum(obs_thr - sdf, s["eps"], 0)
    human = _trilinear(p, s["occ_inv"], occ_packed, occ_first, occ_umax, occ_cmax, occ_strides, occ_offs).sum(0)
    # torso-carried spheres: lift tables
    lift = qt[0]
    u = ((lift - s["lift_lo"]) * s["lift_inv"]).clamp(0, s["lift_n"] - 1)
    i = u.floor().clamp(max=s["lift_n"] - 2)
    tv = tab.index_select(1, i.long())
    fl = u - i
    obstacle = obstacle + torch.lerp(tv[0], tv[1], fl)
    human = human + torch.lerp(tv[2], tv[3], fl)
    if s["self"] and s["pointwise"] and s["n_torso"] >= 0:  # compiled: one fused loop over the pairs
        x = p[:, s["a0"]:s["a1"]]  # (3, A, B)
        nt = s["n_torso"]  # body spheres [0, nt) move with the lift, [nt, B_body) are fixed
        y = x - v[:, :, None] * lift  # the arm points in the frame that moves with the lift
        c0 = psi[:, 8:11].t()[:, :, None, None]  # (3, B_body, 1, 1) centres at lift 0
        dy, dx = y[:, None] - c0[:, :nt], x[:, None] - c0[:, nt:]  # (3, nt, A, B), (3, B_body - nt, A, B)
        rb = psi[:, 7:8, None]
        dist = torch.minimum(((dy * dy).sum(0).clamp(min=1e-12).sqrt() - rb[:nt]).amin(0),
                             ((dx * dx).sum(0).clamp(min=1e-12).sqrt() - rb[nt:]).amin(0))  # (A, B)
        obstacle = obstacle + hinge_sum(s["self_eps"] - (dist - r_arm), s["self_eps"], 0)
    elif s["self"]:  # eager: one matmul of features, then 4 passes over the pairs
        x = p[:, s["a0"]:s["a1"]].reshape(3, -1)  # (3, A * B)
        la = lift.repeat(s["a1"] - s["a0"]).view(1, -1)  # lift per (arm sphere, config)
        phi = torch.cat([x, la * (x * v).sum(0, keepdim=True), torch.ones_like(la), la, la * la], 0)  # (7, A*B)
        d2 = torch.addmm((x * x).sum(0, keepdim=True), psi[:, :7], phi)  # (B_body, A * B)
        dist = (d2.clamp(min=1e-12).sqrt() - psi[:, 7:8]).amin(0).view(-1, b)  # (A, B)
        obstacle = obstacle + hinge_sum(s["self_eps"] - (dist - r_arm), s["self_eps"], 0)
    if s["body"]:  # the person's body as last seen (services.planner.body)
        gap = body_clearances(p, r_carried, BodyCapsules(body_ends, body_radii))  # (S, B)
        obstacle = obstacle + hinge_sum(s["body_eps"] - gap, s["body_eps"] / 2, 0)
    state = torch.stack([s["w_obstacle"] * obstacle, s["w_human"] * human]).view(2, n, t)
    if s["integrate"]:
        dt = waypoint_times(q, inv_vmax)[None].repeat(2, 1, 1)  # (2, N, T)
        dt[1, :, -1] += s["dwell"]  # the human term at the goal: the time the robot stays there
        state = state * dt
    smooth = s["w_smooth"] * acceleration_cost(q)
    return torch.cat([smooth[None], state], 0)


class FusedCost:
    """The planner's waypoint cost (smoothness + time-weighted obstacle and human) as one fused kernel.

    Args:
        robot: The PR2.
        cost: Its :class:`~services.planner.costs.StateCost` (its ``occupancy`` tables are read at every call).
        w_smooth: Weight of the squared accelerations.
        vmax: ``(D,)`` scaled velocity limits (waypoint times).
        integrate: Weight the state terms by the waypoint times (``PlannerConfig.integrate_costs``).
        compile: ``torch.compile`` the kernel (call :meth:`warm_up` with the batch size to compile for).
        grid: The occupancy grid geometry expected (``shared.scene.Grid``, e.g. the scene's): "no occupancy"
            is then a zero grid of the same shape, so the compiled kernel keeps one shape.
        pointwise: The formulation inductor fuses: each arm sphere from its own link's 12 entries and the
            self-collision as one loop over the arm/body sphere pairs, instead of a ``(S, 28)`` product (6/7
            zeros) and a feature matmul; default: when compiled. Calls of a few trajectories, which
            :meth:`terms` runs eagerly next to a compiled kernel, always take the products.
        dwell: With ``integrate``, seconds added to the last waypoint's time in the human term
            (``PlannerConfig.goal_dwell_s``).
    """

    def __init__(self, robot: PR2, cost: StateCost, w_smooth: float, vmax: torch.Tensor, integrate: bool,
                 compile: bool = False, grid: Grid | None = None, pointwise: bool | None = None,
                 dwell: float = 0.0) -> None:
        if not supports(robot, cost):
            raise ValueError("FusedCost needs a PR2 StateCost with lift tables, 1 point per sphere, trilinear")
        self.robot, self.cost = robot, cost
        dev, dt = robot.device, robot.dtype
        cfg = cost.config
        a0, a123t = robot.kinematics.transform_basis(robot.base_transform)
        arm = robot.arm_carried_slice
        w = robot.spheres.weights[2:len(robot.link_names) - 1, :, arm]  # (7, 4, S) links of the arm joints
        sph_link = (robot.sphere_anchor[arm] - 2).to(dev)  # (S,) each sphere's link among those 7 (`supports`)
        sph_local = w[sph_link, :, torch.arange(len(sph_link), device=dev)][:, :, None].contiguous()  # (S, 4, 1)
        r_arm_c = robot.sphere_radii[arm]
        # static field, cropped to where some arm-carried sphere can pay (value < clearance + largest radius)
        sdf = cost.sdf
        field = sdf.tables
        vol = field.volume
        cap = cfg.clearance + float(r_arm_c.max())
        sub, first, inside = crop_volume(vol, field.first, 1.0 / field.inv_res, vol < cap)
        self._sdf = VoxelTables.build(sub, first, field.inv_res)
        # body spheres: centre(l) = c0 + l v (torso-carried) or c0 (fixed base)
        lo = robot.lower.clone()
        up = lo.clone()
        up[0] = robot.upper[0]
        body = robot.body_slice
        c_lo, c_up = robot.sphere_centers(lo)[body].double(), robot.sphere_centers(up)[body].double()
        vb = (c_up - c_lo) / float(robot.upper[0] - robot.lower[0])  # (Bb, 3): the torso axis or 0
        moving = vb.norm(dim=1) > 0.5
        z = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64, device=vb.device)
        axis = vb[moving].mean(0) if bool(moving.any()) else z
        axis = axis / axis.norm()
        kappa = moving.double()
        c0 = c_lo - float(robot.lower[0]) * kappa[:, None] * axis
        psi = torch.cat([-2 * c0, -2 * kappa[:, None], (c0 * c0).sum(1, keepdim=True),
                         (2 * kappa * (c0 @ axis))[:, None], kappa[:, None],
                         robot.sphere_radii[body].double()[:, None], c0, kappa[:, None] * axis], 1)
        # psi (Bb, 14): 7 feature coefficients, radius, centre at lift 0, lift velocity
        self._consts = dict(a0=a0.to(dev, dt), a123t=a123t.contiguous().to(dev, dt),
                            wt=w.reshape(-1, w.shape[-1]).t().contiguous(),
                            sph_link=sph_link, sph_local=sph_local,
                            obs_thr=(cfg.clearance + r_arm_c)[:, None].contiguous(),
                            sdf_lo=torch.as_tensor(sdf.grid.min, device=dev, dtype=dt).reshape(3, 1, 1),
                            sdf_hi=torch.as_tensor(sdf.grid.max, device=dev, dtype=dt).reshape(3, 1, 1),
                            psi=psi.to(dev, dt).contiguous(), v=axis.to(dev, dt).reshape(3, 1),
                            r_arm=robot.sphere_radii[robot.arm_slice][:, None].contiguous(),
                            inv_vmax=(1.0 / vmax).to(dev, dt).contiguous(), r_carried=r_arm_c.contiguous())
        n_torso = int(moving.sum())
        contiguous = bool(moving[:n_torso].all()) and n_torso < len(moving)
        lift = cost.occupancy.lift
        self._static = dict(n_torso=n_torso if contiguous else -1, sdf_inv=field.inv_res, sdf_extend=not inside,
                            eps=float(cfg.clearance),
                            occ_inv=1.0, lift_lo=float(lift.lo), lift_inv=1.0 / float(lift.step),
                            lift_n=int(lift.n), self=bool(cost.has_self),
                            a0=robot.arm_slice.start - arm.start, a1=robot.arm_slice.stop - arm.start,
                            self_eps=max(float(cfg.self_clearance), 1e-6), w_obstacle=float(cfg.w_obstacle),
                            w_human=float(cfg.w_human), w_smooth=float(w_smooth), integrate=bool(integrate),
                            dwell=float(dwell), body=cfg.body_clearance > 0, body_eps=float(cfg.body_clearance))
        self._far = BodyCapsules.far(len(HumanModel.SEGMENT_NAMES), dev, dt)  # the body while none is set
        if grid is None:
            zeros, first, inv_res = torch.zeros(2, 2, 2, device=dev, dtype=dt), torch.zeros(3), 1.0
        else:  # the zero-padded shape and geometry of a real occupancy on `grid` (see VoxelTables.from_grid)
            res = float(grid.resolution)
            zeros = torch.zeros(*[int(n) + 2 for n in grid.dims], device=dev, dtype=dt)
            first, inv_res = torch.as_tensor(grid.origin, dtype=torch.float64) - res / 2, 1.0 / res
        self._no_occupancy = VoxelTables.build(zeros, first, inv_res)  # read while no occupancy is set
        self._geometry = self._occupancy_geometry(self._no_occupancy) if grid is not None else None
        self.eager_geometries: set[tuple[tuple[int, ...], float]] = set()  # occupancy geometries costed eagerly
        self.pointwise = pointwise
        self._set_mode(bool(compile))
        self.batch: int | None = None  # the compiled batch size N (trajectories per call), set by warm_up
        self.compile_s = 0.0

    def _set_mode(self, compiled: bool) -> None:
        """Compiled: the pointwise formulation fused by inductor; eager: products and a feature matmul."""
        self.compiled = compiled
        # the lookups' indices are clamped into range (see _trilinear): inductor's per-lane index asserts are moot
        # one code object for every FusedCost of the process, so room for all their shapes (planner.compiling)
        self._fn: Callable[..., torch.Tensor] = (
            compile_every_shape(_kernel, dynamic=False, options={"assert_indirect_indexing": False}) if compiled
            else _kernel)
        self._static.update(pointwise=compiled if self.pointwise is None else self.pointwise)
        self._flat = compiled  # compiled: 8 gathers from the volume itself (8x smaller than the packed cells)

    @staticmethod
    def _occupancy_geometry(tables: VoxelTables) -> tuple[tuple[int, ...], float]:
        """What a compiled kernel is specialised on: the occupancy volume's shape and its resolution."""
        return tuple(tables.volume.shape), float(tables.inv_res)

    def _run(self, q3: torch.Tensor, eager: bool = False) -> torch.Tensor:
        c = self._consts
        tables = self.cost.occupancy  # rebuilt by StateCost.set_occupancy, once per grid
        occ = tables.voxels if tables.voxels is not None else self._no_occupancy
        assert tables.lift is not None
        body = self.cost.body if self.cost.body is not None else self._far
        s = dict(self._static, occ_inv=occ.inv_res)
        if self.compiled and not eager and self._geometry is not None:
            # an occupancy on another grid than the scene's (a model trained at another --resolution): compiling for
            # it stalled one step for 33 s on 2 CPUs (the robot held); the same kernel runs eagerly instead
            geometry = self._occupancy_geometry(occ)
            if geometry != self._geometry:
                eager = True
                if geometry not in self.eager_geometries:
                    self.eager_geometries.add(geometry)
                    log.warning("occupancy grid %s at %.3g m is not the scene grid %s at %.3g m the planner's cost "
                                "was compiled for: costed eagerly (about 3x slower per call; train the model at "
                                "the scene grid's resolution to avoid it)", "x".join(map(str, geometry[0])),
                                1.0 / geometry[1], "x".join(map(str, self._geometry[0])), 1.0 / self._geometry[1])
        fn, flat = self._fn, self._flat
        if eager:
            fn, s["pointwise"] = _kernel, False
        return fn(q3, c["a0"], c["a123t"], c["wt"], c["sph_link"], c["sph_local"], c["obs_thr"],
                  *_cell_args(self._sdf, flat), c["sdf_lo"], c["sdf_hi"], *_cell_args(occ, flat), tables.lift.values,
                  c["psi"], c["v"], c["r_arm"], c["inv_vmax"], body.ends, body.radii, c["r_carried"], s=s)

    def terms(self, q: torch.Tensor) -> torch.Tensor:
        """Per-waypoint terms.

        Args:
            q: ``(..., T, D)`` trajectories.

        Returns:
            ``(3, ..., T)``: ``w_smooth`` x squared acceleration, obstacle, human (the state terms weighted
            and, with ``integrate``, times the waypoint time, the human's at the goal plus ``dwell``), as
            ``Planner.waypoint_cost_reference`` sums.
        """
        lead, (t, d) = q.shape[:-2], q.shape[-2:]
        q3 = q.reshape(-1, t, d).to(self.robot.dtype)
        n = q3.shape[0]
        if not self.compiled or self.batch is None or n == self.batch:
            out = self._run(q3)
        elif 4 * n <= self.batch:  # a few trajectories (final costs): cheaper eager than a padded compiled call
            out = self._run(q3, eager=True)
        else:  # the compiled shape: chunks of `batch` trajectories, the last one padded
            chunks = -(-n // self.batch)
            pad = chunks * self.batch - n
            if pad:
                q3 = torch.cat([q3, q3[:1].expand(pad, t, d)], 0)
            out = torch.cat([self._run(q3[i * self.batch:(i + 1) * self.batch]) for i in range(chunks)], 1)[:, :n]
        return out.reshape(3, *lead, t)

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        """Total cost per waypoint: ``q`` ``(K, R, T, D)`` -> ``(K, R, T)`` (what STOMP optimises)."""
        return self.terms(q).sum(0)

    def warm_up(self, batch: int, waypoints: int) -> float:
        """Fix the batch size (trajectories per kernel call) and, when compiled, compile for it.

        Returns:
            Seconds spent (the compilation).
        """
        q = (self.robot.lower + 0.5 * (self.robot.upper - self.robot.lower)).expand(batch, waypoints, -1).contiguous()
        t0 = time.perf_counter()
        self.batch = int(batch)
        try:
            self._run(q)
        except Exception as exc:  # no C++ compiler, unsupported backend...: the same kernel, eager
            if not self.compiled:
                raise
            log.warning("torch.compile of the planner cost failed (%s: %s); running it eagerly",
                        type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")
            self._set_mode(False)
            self._run(q)
        self.compile_s = time.perf_counter() - t0
        if self.compiled:
            log.info("planner cost compiled for %d trajectories in %.1f s", self.batch, self.compile_s)
        return self.compile_s

