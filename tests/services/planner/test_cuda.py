"""The planner on a CUDA device: the CPU's costs, valid plans, and the same plan for the same seed.

Skipped where torch sees no CUDA device (CI has none). On a machine with one:
``pytest tests/services/planner/test_cuda.py``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from services.planner.bench import bench_goals, blob_occupancy, start_configuration
from services.planner.core import Planner, PlannerConfig
from services.planner.stomp import StompConfig

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(),
                                reason="no CUDA device here (torch.cuda.is_available() is False)")

CONFIG = PlannerConfig(stomp=StompConfig(iterations=10), compile=False)


def _planner(scene, device: str, compile: bool = False) -> Planner:
    """Three goals (the bench's: the scene's IK goals, then seeded perturbations) on ``device``."""
    config = dataclasses.replace(CONFIG, device=device, compile=compile)
    base = Planner(scene, config)
    return Planner(scene, config, robot=base.robot, cost=base.cost,
                   goals=bench_goals(base.goals, base.robot, 3, seed=0))


@pytest.fixture(scope="module")
def cpu(scene) -> Planner:
    return _planner(scene, "cpu")


@pytest.fixture(scope="module")
def gpu(scene) -> Planner:
    return _planner(scene, "cuda")


def _batch(robot, shape: tuple[int, ...], seed: int, spread: float = 0.6) -> torch.Tensor:
    """CPU configurations around the start (some in the table, some against the body), within the limits."""
    g = torch.Generator().manual_seed(seed)
    lower, upper, start = robot.lower.cpu(), robot.upper.cpu(), robot.q_start.cpu()
    scale = torch.full((lower.shape[0],), spread, dtype=lower.dtype)
    scale[0] = 0.1
    q = start + scale * torch.randn(*shape, lower.shape[0], generator=g, dtype=lower.dtype)
    return torch.minimum(torch.maximum(q, lower), upper)


def test_goals_are_the_same_on_both_devices(cpu, gpu) -> None:
    assert gpu.goals.names == cpu.goals.names
    assert torch.allclose(gpu.goals.q.cpu().double(), cpu.goals.q.cpu().double(), atol=1e-5)


@pytest.mark.parametrize("occupancy", ["blob", "uniform", "none"])
def test_costs_on_cuda_equal_the_cpu_costs(cpu, gpu, scene, occupancy: str) -> None:
    """Fused kernel and unfused reference, on the same configurations, on both devices."""
    grid = scene.grid
    occ = {"blob": blob_occupancy(scene), "none": None,
           "uniform": np.random.default_rng(0).uniform(0, 1, grid.dims).astype(np.float32)}[occupancy]
    try:
        for p in (cpu, gpu):
            p.cost.set_occupancy(occ, grid.origin, grid.resolution)
        for seed in range(3):
            q = _batch(cpu.robot, (3, 5, 40), seed)
            want = cpu.waypoint_cost(q)
            got = gpu.waypoint_cost(q.to(gpu.device))
            ref = gpu.waypoint_cost_reference(q.to(gpu.device))
            assert got.device.type == "cuda" and got.shape == want.shape == (3, 5, 40)
            assert float(want.max()) > 1.0  # the obstacle and self-collision terms are exercised
            assert torch.allclose(got.cpu(), want, rtol=1e-4, atol=1e-3), float((got.cpu() - want).abs().max())
            assert torch.allclose(ref.cpu(), want, rtol=1e-4, atol=1e-3), float((ref.cpu() - want).abs().max())
    finally:
        for p in (cpu, gpu):
            p.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_compiled_cuda_kernel_equals_the_cpu_cost(cpu, scene) -> None:
    """What the planner runs on a GPU by default: the fused cost compiled by torch.compile (Triton)."""
    grid = scene.grid
    gpu = _planner(scene, "cuda", compile=True)
    if gpu.fused is None or not gpu.fused.compiled:
        pytest.skip("torch.compile is not available for CUDA here: the kernel fell back to eager")
    occ = blob_occupancy(scene)
    try:
        for p in (cpu, gpu):
            p.cost.set_occupancy(occ, grid.origin, grid.resolution)
        q = _batch(cpu.robot, (3, 11, 40), 11, spread=1.0)
        want, got = cpu.waypoint_cost(q), gpu.waypoint_cost(q.to(gpu.device))
        assert torch.allclose(got.cpu(), want, rtol=1e-4, atol=1e-3), float((got.cpu() - want).abs().max())
    finally:
        for p in (cpu, gpu):
            p.cost.set_occupancy(None, grid.origin, grid.resolution)


def test_a_cuda_plan_is_valid_and_as_good_as_the_cpu_plan(cpu, gpu, scene) -> None:
    """Host arrays out, start kept, limits kept, goals reached; the least cost within 25 % of the CPU's.

    The two devices draw STOMP's noise from different generators, so the plans differ; the cost each reaches
    should not.
    """
    occ = blob_occupancy(scene)
    q0 = start_configuration(cpu.robot)
    lower, upper = cpu.robot.lower.cpu().numpy(), cpu.robot.upper.cpu().numpy()
    least = {}
    for name, p in (("cpu", cpu), ("cuda", gpu)):
        res = p.step(q0, occ)
        res = p.step(res.start, occ)
        assert isinstance(res.trajectories, np.ndarray) and res.trajectories.shape[0] == 3
        assert res.valid.all() and np.isfinite(res.cost_total).all()
        assert np.allclose(res.trajectories[:, 0], res.start, atol=1e-6)
        assert (res.trajectories >= lower - 1e-5).all() and (res.trajectories <= upper + 1e-5).all()
        assert np.allclose(res.trajectories[:, -1], p.goals.q.cpu().numpy(), atol=1e-4)
        least[name] = float(res.cost_total.min())
    assert least["cuda"] == pytest.approx(least["cpu"], rel=0.25), least


def test_the_same_seed_gives_the_same_cuda_plan(scene) -> None:
    """Lock-step runs give the same numbers on every run, on a GPU too."""
    occ = blob_occupancy(scene)
    runs = []
    for _ in range(2):
        p = _planner(scene, "cuda")
        res = p.step(start_configuration(p.robot), occ)
        res = p.step(res.start, occ)
        runs.append(res)
    assert np.array_equal(runs[0].trajectories, runs[1].trajectories)
    assert np.array_equal(runs[0].cost_total, runs[1].cost_total)
