"""The fused planner cost equals the reference path (StateCost x waypoint time + smoothness)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from services.planner.bench import bench_goals, blob_occupancy
from services.planner.core import Planner, PlannerConfig
from services.planner.costs import CostConfig, StateCost
from services.planner.fused import FusedCost, supports
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
    q = robot.q_start + scale * torch.randn(*shape, 8, generator=g)
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
            assert torch.allclose(out, ref, rtol=1e-5, atol=1e-4), float((out - ref).abs().max())
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)


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
    self_term = cost._self_term(robot.sphere_centers(q))
    assert float(self_term.max()) > 0.01 and bool((self_term == 0).any())  # some contacts, some free
    centres = robot.sphere_centers(q)[..., robot.arm_carried_slice, :]
    outside = ((centres < torch.as_tensor(cost.sdf.grid.min, dtype=torch.float32))
               | (centres > torch.as_tensor(cost.sdf.grid.max, dtype=torch.float32))).any(-1)
    assert bool(outside.any())  # some spheres leave the field's grid
    # float32: both sides expand |a - b|^2 = |a|^2 + |b|^2 - 2 a.b in world coordinates (~1 m), so sphere
    # distances agree to ~1e-5 m; weighted (x 10) and summed over 16 spheres that is a few 1e-4
    assert torch.allclose(out, ref, rtol=1e-4, atol=5e-4), float((out - ref).abs().max())
    fused._static["self_pairs"] = True  # the pair loop the compiled kernel uses (here run eagerly)
    pairs = fused.terms(q[:, :, None].expand(20, 20, 3, 8))[1, :, :, 1]
    assert torch.allclose(pairs, ref, rtol=1e-4, atol=5e-4), float((pairs - ref).abs().max())


def test_chunked_batches_equal_one_call(planner, scene) -> None:
    """The compiled path evaluates fixed-size chunks (the last one padded): same numbers as one call."""
    grid = scene.grid
    planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
    f = FusedCost(planner.robot, planner.cost, planner.w_smooth, planner._vmax, True)
    q = _batch(planner.robot, (3, 7, 40), 5)
    whole = f(q)
    f.compiled, f.batch = True, 4  # chunks of 4 trajectories, eager kernel
    assert torch.allclose(f(q), whole, atol=1e-6)
    assert torch.allclose(f(q[:, :1]), whole[:, :1], atol=1e-6)
    f.batch = 12  # 3 trajectories: the small-batch path
    assert torch.allclose(f(q[:, :1]), whole[:, :1], atol=1e-6)
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_unsupported_costs_keep_the_reference_path(scene) -> None:
    robot = PR2.from_scene(scene)
    seven = StateCost.from_scene(scene, robot, CostConfig(human_points=7, sdf_resolution=0.05))
    assert not supports(robot, seven)
    with pytest.raises(ValueError, match="FusedCost"):
        FusedCost(robot, seven, 10.0, robot.velocity_limits, True)


def test_flat_volume_lookups_equal_packed_cells(planner, scene) -> None:
    """The compiled kernel gathers the 8 corners from the volume itself; eager from packed cells."""
    from services.planner.fused import _Cells

    grid = scene.grid
    planner.cost.set_occupancy(blob_occupancy(scene), grid.origin, grid.resolution)
    f = FusedCost(planner.robot, planner.cost, planner.w_smooth, planner._vmax, True, grid=grid)
    q = _batch(planner.robot, (2, 6, 40), 11, spread=1.2)
    packed = f(q)
    f._flat, f._sdf, f._occ_src = True, _Cells(*f._sdf_args, flat=True), object()
    assert f._sdf.packed.dim() == 1
    assert torch.allclose(f(q), packed, rtol=1e-6, atol=1e-6)
    planner.cost.set_occupancy(None, grid.origin, grid.resolution)
