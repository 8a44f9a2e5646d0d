"""The fused planner cost equals the reference path (StateCost x waypoint time + smoothness)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from services.planner import fused as fused_module
from services.planner.bench import bench_goals, blob_occupancy
from services.planner.core import GoalSet, Planner, PlannerConfig
from services.planner.costs import CostConfig, StateCost, hinge_sum
from services.planner.fused import FusedCost, _cell_args, _trilinear, supports
from services.planner.stomp import StompConfig
from shared.robot import PR2


@pytest.fixture(scope="module")
def planner(scene):
    config = PlannerConfig(stomp=StompConfig(iterations=5), compile=False)
    base = Planner(scene, config)
    goals = bench_goals(base.goals, base.robot, 3, seed=0)
    return Planner(scene, config, robot=base.robot, cost=base.cost, goals=goals)


def _batch(robot: PR2, shape: tuple[int, ...], seed: int, spread: float = 0.6) -> torch.Tensor:
    """Configurations around the start (some in the table, some against the body) within the limits."""
    g = torch.Generator().manual_seed(seed)
    scale = torch.full((8,), spread)
    scale[0] = 0.1
    q = robot.q_start + scale.to(robot.dtype) * torch.randn(*shape, 8, generator=g, dtype=robot.dtype)
    return torch.minimum(torch.maximum(q, robot.lower), robot.upper)


def test_fused_equals_reference_on_random_batches(planner, scene) -> None:
    assert planner.fused is not None and supports(planner.robot, planner.cost)
    grid = scene.grid
    rng = np.random.default_rng(0)
    for occ in (blob_occupancy(scene), rng.uniform(0, 1, grid.dims).astype(np.float32), None):
        planner.cost.set_occupancy(occ, grid.origin, grid.resolution)
        for seed in range(3):
            q = _batch(planner.robot, (3, 5, 40), seed)
            ref = planner.waypoint_cost_reference(q)
            out = planner.waypoint_cost(q)
            assert out.shape == ref.shape == (3, 5, 40)
            # float32 rounding: the kernel sums the sphere terms in another order, and every waypoint carries the
            # path's dt, so the largest state terms carry the largest weights (up to 3.3e-5 relative here); in
            # float64 the two agree to ~1e-9 (below)
            assert torch.allclose(out, ref, rtol=1e-4, atol=1e-4), float((out - ref).abs().max())
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)


@pytest.mark.parametrize("dwell", [0.0, 2.5])
def test_fused_equals_reference_in_float64(scene, dwell: float) -> None:
    """In float64 the two implementations agree to ~1e-9: the float32 tolerances above are rounding only."""
    robot = PR2.from_scene(scene, dtype=torch.float64)
    cost = StateCost.from_scene(scene, robot, CostConfig())
    goals = GoalSet.joint_space(["start"], robot.q_start[None], robot)
    config = PlannerConfig(dtype="float64", compile=False, stomp=StompConfig(iterations=1), goal_dwell_s=dwell)
    planner = Planner(scene, config, robot=robot, cost=cost, goals=goals)
    assert planner.fused is not None
    # the compiled kernel's formulation (each sphere from its own link, the self-collision pair loop), run eagerly
    pointwise = FusedCost(robot, cost, planner.w_smooth, _vmax(planner), True, grid=scene.grid, dwell=dwell,
                          pointwise=True)
    grid = scene.grid
    rng = np.random.default_rng(2)
    for occ in (blob_occupancy(scene), rng.uniform(0, 1, grid.dims), None):
        cost.set_occupancy(occ, grid.origin, grid.resolution)
        q = _batch(robot, (4, 6, 40), 9, spread=1.0)
        ref, out = planner.waypoint_cost_reference(q), planner.waypoint_cost(q)
        assert float(ref.max()) > 1.0  # obstacle and self-collision terms are exercised
        assert torch.allclose(out, ref, rtol=1e-9, atol=1e-9), float((out - ref).abs().max())
        out = pointwise(q)
        assert torch.allclose(out, ref, rtol=1e-9, atol=1e-9), float((out - ref).abs().max())


def test_fused_terms_match_each_reference_term(planner, scene) -> None:
    grid = scene.grid
    planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
    q = _batch(planner.robot, (6, 40), 7, spread=1.0)
    fused = planner.cost_terms(q)
    keep, planner.fused = planner.fused, None
    try:
        ref = planner.cost_terms(q)
    finally:
        planner.fused = keep
    assert float(ref["obstacle"].max()) > 0.1 and float(ref["human"].max()) > 0.01  # the terms are exercised
    for name in ("smoothness", "obstacle", "human", "total"):
        assert torch.allclose(fused[name], ref[name], rtol=1e-5, atol=1e-4), name
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_self_collision_and_cropped_field_are_exact(scene) -> None:
    """Per-waypoint obstacle term (no time weights) against StateCost: arm against the body, in the
    table, and outside the static field's grid (where the cropped field has no extension)."""
    robot = PR2.from_scene(scene)
    cost = StateCost.from_scene(scene, robot, CostConfig())
    fused = FusedCost(robot, cost, 0.0, robot.velocity_limits, integrate=False)
    q = _batch(robot, (400,), 3, spread=1.5).reshape(20, 20, 8)  # wide: body contacts, far reaches
    ref = cost(q)[..., 0]
    out = fused.terms(q[:, :, None].expand(20, 20, 3, 8))[1, :, :, 1]  # middle waypoint, obstacle
    eps = cost.config.self_clearance
    self_term = hinge_sum(eps - robot.self_collision_distance(robot.sphere_centers(q)).amin(-1), eps)
    assert float(self_term.max()) > 0.01 and bool((self_term == 0).any())  # some contacts, some free
    centres = robot.sphere_centers(q)[..., robot.arm_carried_slice, :]
    outside = ((centres < torch.as_tensor(cost.sdf.grid.min, dtype=torch.float32))
               | (centres > torch.as_tensor(cost.sdf.grid.max, dtype=torch.float32))).any(-1)
    assert bool(outside.any())  # some spheres leave the field's grid
    # float32: both sides expand |a - b|^2 = |a|^2 + |b|^2 - 2 a.b in world coordinates (~1 m), so sphere
    # distances agree to ~1e-5 m; weighted (x 10) and summed over 16 spheres that is a few 1e-4
    assert torch.allclose(out, ref, rtol=1e-4, atol=5e-4), float((out - ref).abs().max())
    pairs_kernel = FusedCost(robot, cost, 0.0, robot.velocity_limits, integrate=False, pointwise=True)
    pairs = pairs_kernel.terms(q[:, :, None].expand(20, 20, 3, 8))[1, :, :, 1]  # the compiled formulation, eager
    assert torch.allclose(pairs, ref, rtol=1e-4, atol=5e-4), float((pairs - ref).abs().max())


def test_chunked_batches_equal_one_call(planner, scene) -> None:
    """The compiled path evaluates fixed-size chunks (the last one padded): same numbers as one call."""
    grid = scene.grid
    planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
    f = FusedCost(planner.robot, planner.cost, planner.w_smooth, _vmax(planner), True)
    q = _batch(planner.robot, (3, 7, 40), 5)
    whole = f(q)
    f.compiled, f.batch = True, 4  # chunks of 4 trajectories, eager kernel
    assert torch.allclose(f(q), whole, atol=1e-6)
    assert torch.allclose(f(q[:, :1]), whole[:, :1], atol=1e-6)
    f.batch = 12  # 3 trajectories: the small-batch path
    assert torch.allclose(f(q[:, :1]), whole[:, :1], atol=1e-6)
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_an_occupancy_on_another_grid_is_costed_eagerly_not_recompiled(planner, scene, caplog) -> None:
    """A model trained at another resolution than the scene grid's: the compiled kernel, specialised on the scene
    grid's shape and resolution, recompiled for it (33 s on 2 CPUs, one step; the robot held). It runs eagerly."""
    grid = scene.grid
    calls = []

    def compiled(*args, s):  # stands in for the torch.compile-d kernel: counts its calls, computes eagerly
        calls.append(1)
        return fused_module._kernel(*args, s=dict(s, pointwise=False))

    f = FusedCost(planner.robot, planner.cost, planner.w_smooth, _vmax(planner), True, grid=grid)
    f.compiled, f.batch, f._fn = True, 3, compiled
    q = _batch(planner.robot, (3, 40), 7)
    try:
        planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
        f(q)
        assert len(calls) == 1  # the scene grid: the compiled kernel
        coarse = blob_occupancy(scene)[::2, ::2, ::2]  # the same bounds at twice the voxel edge
        planner.cost.set_occupancy(coarse, grid.origin, 2 * grid.resolution)
        reference = FusedCost(planner.robot, planner.cost, planner.w_smooth, _vmax(planner), True, grid=grid)(q)
        with caplog.at_level("WARNING", logger="foresight.planner"):
            out, again = f(q), f(q)
        assert len(calls) == 1 and torch.equal(out, reference) and torch.equal(again, reference)
        warned = [r.getMessage() for r in caplog.records if "costed eagerly" in r.getMessage()]
        assert len(warned) == 1 and f"at {2 * grid.resolution:.3g} m is not the scene grid" in warned[0], warned
        planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
        f(q)
        assert len(calls) == 2  # back on the scene grid: compiled again
    finally:
        planner.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_compiled_kernel_equals_reference(planner, scene) -> None:
    """The torch.compile-d kernel (what the planner runs by default) against the reference path."""
    grid = scene.grid
    planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
    try:
        f = FusedCost(planner.robot, planner.cost, planner.w_smooth, _vmax(planner), True, compile=True, grid=grid,
                      dwell=planner.config.goal_dwell_s)
        f.warm_up(2 * 5, 40)
        if not f.compiled:
            pytest.skip("torch.compile is not available here (no C++ compiler): the kernel fell back to eager")
        q = _batch(planner.robot, (2, 5, 40), 11, spread=1.0)
        ref, out = planner.waypoint_cost_reference(q), f(q)
        assert float(ref.max()) > 1.0  # obstacle and self-collision terms are exercised
        assert torch.allclose(out, ref, rtol=1e-5, atol=1e-4), float((out - ref).abs().max())
    finally:
        planner.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_unsupported_costs_keep_the_reference_path(scene) -> None:
    robot = PR2.from_scene(scene)
    seven = StateCost.from_scene(scene, robot, CostConfig(human_points=7, sdf_resolution=0.05))
    assert not supports(robot, seven)
    with pytest.raises(ValueError, match="FusedCost"):
        FusedCost(robot, seven, 10.0, robot.velocity_limits, True)


def test_kernel_lookups_equal_the_reference_lookups(planner, scene) -> None:
    """The kernel reads the same VoxelTables as the reference: its packed cells (eager) or the flat volume
    (compiled), with lerps instead of the reference's ``a + (b - a) f`` (equal to float32 rounding)."""
    grid = scene.grid
    planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
    g = torch.Generator().manual_seed(3)
    lo, hi = torch.as_tensor(grid.min) - 0.1, torch.as_tensor(grid.max) + 0.1  # some points beyond the grid
    p = (lo + (hi - lo) * torch.rand(2000, 3, generator=g, dtype=torch.float64)).float()
    for tables in (planner.cost.occupancy.voxels, planner.cost.sdf.tables):
        ref = tables.lookup(p)
        assert float(ref.abs().max()) > 0.1  # the points see the values
        for flat in (False, True):
            out = _trilinear(p.t().reshape(3, 1, -1), tables.inv_res, *_cell_args(tables, flat)).reshape(-1)
            assert torch.allclose(out, ref, rtol=1e-6, atol=1e-6), (flat, float((out - ref).abs().max()))
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)


def _vmax(planner: Planner) -> torch.Tensor:
    """The planner's scaled velocity limits (its waypoint times)."""
    return planner.robot.velocity_limits * planner.config.velocity_scale
