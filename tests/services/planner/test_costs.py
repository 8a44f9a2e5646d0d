"""Planning costs: smooth penetration, smoothness, the PR2 state cost (obstacle + human)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from services.planner.costs import (
    CostConfig,
    CostInputError,
    StateCost,
    acceleration_cost,
    hinge_sum,
    path_dt,
    waypoint_times,
)


@pytest.fixture(scope="module")
def cost(scene, robot):
    return StateCost.from_scene(scene, robot, CostConfig(sdf_resolution=0.03))


def test_hinge_shape() -> None:
    eps = 0.05
    d = torch.tensor([-0.1, -1e-6, 0.0, 0.025, eps - 1e-7, eps, 0.2])
    c = hinge_sum((eps - d)[:, None], eps)  # one element per sum: the hinge itself
    assert float(c[0]) == pytest.approx(eps / 2 + 0.1)
    assert float(c[1]) == pytest.approx(eps / 2, abs=1e-5) and float(c[2]) == pytest.approx(eps / 2)  # continuous at 0
    assert float(c[3]) == pytest.approx(0.025**2 / (2 * eps))
    assert float(c[4]) == pytest.approx(0.0, abs=1e-6) and float(c[5]) == 0 and float(c[6]) == 0
    assert torch.all(c[:-1] >= c[1:])  # non-increasing in d
    assert float(hinge_sum(eps - d, eps)) == pytest.approx(float(c.sum()), rel=1e-6)  # sums over the last axis


def test_acceleration_cost() -> None:
    t = torch.linspace(0, 1, 20)
    line = torch.stack([t, 2 * t, -t], -1)
    assert float(acceleration_cost(line).sum()) == pytest.approx(0.0, abs=1e-10)
    quad = (t**2)[:, None].repeat(1, 2)
    h = float(t[1] - t[0])
    per = acceleration_cost(quad)
    assert per.shape == (20,) and float(per[0]) == float(per[-1]) == 0.0  # ends: no acceleration
    expect = 18 * 2 * (2 * h * h) ** 2  # 18 interior waypoints x 2 joints x (second difference)^2
    assert float(per.sum()) == pytest.approx(expect, rel=1e-4)
    batch = torch.stack([line, quad[:, :1].repeat(1, 3)])
    assert acceleration_cost(batch).shape == (2, 20)
    with pytest.raises(CostInputError, match="3 waypoints"):
        acceleration_cost(torch.zeros(2, 3))


def test_state_cost_shape_and_start_is_free(cost, robot) -> None:
    q = robot.q_start.expand(2, 3, 5, 8)
    out = cost(q)
    assert out.shape == (2, 3, 5, 2)
    assert torch.all(out == 0)  # start configuration: clear of the table, no occupancy set
    assert bool(cost.collision_free(robot.q_start))


def test_obstacle_cost_penalises_the_hand_in_the_table(cost, robot, scene) -> None:
    # hand pushed down into the table top: shoulder lift down, elbow straight
    q_down = robot.q_start.clone()
    q_down[1:] = torch.tensor([0.3, 1.0, 0.0, -0.3, 0.0, -0.3, 0.0])
    assert float(robot.end_effector(q_down)[2, 3]) < scene.boxes[0].upper[2]
    c = cost(q_down[None])[0]
    assert float(c[0]) > 0.1
    assert not bool(cost.collision_free(q_down))
    assert float(cost.clearance(q_down)) < 0


def test_human_cost_reads_occupancy_at_the_spheres(scene, robot) -> None:
    cost = StateCost.from_scene(scene, robot, CostConfig(sdf_resolution=0.05, w_human=2.0))
    grid = scene.grid
    occ = np.zeros(grid.dims, dtype=np.float32)
    hand = robot.end_effector(robot.q_start)[:3, 3].numpy()
    idx, inside = grid.index(hand[None])
    assert inside[0]
    i, j, k = idx[0]
    occ[i - 2:i + 3, j - 2:j + 3, k - 2:k + 3] = 0.8
    cost.set_occupancy(occ, grid.origin, grid.resolution)
    h = cost(robot.q_start[None])[0, 1]
    raw = cost.human(robot.sphere_centers(robot.q_start[None]))[0]
    assert float(raw) > 0.8  # several spheres of the hand inside the blob
    assert float(h) == pytest.approx(2.0 * float(raw), rel=1e-5)
    # the blob moved far away: no human cost
    cost.set_occupancy(np.roll(occ, 20, axis=0), grid.origin, grid.resolution)
    assert float(cost(robot.q_start[None])[0, 1]) == 0.0
    cost.set_occupancy(None, grid.origin, grid.resolution)
    assert float(cost(robot.q_start[None])[0, 1]) == 0.0


def test_human_cost_nearest_and_seven_points(scene, robot) -> None:
    grid = scene.grid
    occ = np.full(grid.dims, 0.25, dtype=np.float32)
    for interp, pts in (("nearest", 1), ("trilinear", 7)):
        cost = StateCost.from_scene(scene, robot, CostConfig(sdf_resolution=0.05, human_interp=interp,
                                                             human_points=pts))
        cost.set_occupancy(occ, grid.origin, grid.resolution)
        n = robot.moving_spheres.numel()
        assert float(cost(robot.q_start[None])[0, 1]) == pytest.approx(0.25 * n, rel=1e-4)


def test_batched_equals_looped(cost, robot, scene) -> None:
    grid = scene.grid
    rng = np.random.default_rng(0)
    cost.set_occupancy(rng.uniform(0, 1, grid.dims).astype(np.float32), grid.origin, grid.resolution)
    g = torch.Generator().manual_seed(0)
    q = robot.q_start + 0.4 * torch.randn(2, 4, 6, 8, generator=g)
    q = torch.minimum(torch.maximum(q, robot.lower), robot.upper)
    batched = cost(q)
    looped = torch.stack([cost(qi[None])[0] for qi in q.reshape(-1, 8)]).reshape(batched.shape)
    assert torch.allclose(batched, looped, atol=1e-5)
    cost.set_occupancy(None, grid.origin, grid.resolution)


@pytest.mark.parametrize("occ,origin,res,match", [
    (np.zeros((4, 4)), np.zeros(3), 0.05, "nx, ny, nz"),
    (np.full((4, 4, 4), np.nan), np.zeros(3), 0.05, "NaN"),
    (np.full((4, 4, 4), 1.5), np.zeros(3), 0.05, r"\[0, 1\]"),
    (np.zeros((4, 4, 4)), np.zeros(3), 0.0, "resolution"),
    (np.zeros((4, 4, 4)), [0.0, np.inf, 0.0], 0.05, "origin"),
])
def test_set_occupancy_rejects_bad_grids(cost, occ, origin, res, match) -> None:
    with pytest.raises(CostInputError, match=match):
        cost.set_occupancy(occ, origin, res)


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="human_points"):
        CostConfig(human_points=3).validate()
    with pytest.raises(ValueError, match="clearance"):
        CostConfig(clearance=0).validate()
    # an infinite weight or margin made every step's costs NaN (inf * 0, inf - inf): no plan could be sent
    for field in ("w_smooth", "w_obstacle", "w_human", "clearance", "self_clearance", "sdf_resolution",
                  "torso_table_step"):
        for bad in (math.inf, math.nan):
            with pytest.raises(ValueError, match=rf"costs\.{field}: bad value"):
                CostConfig(**{field: bad}).validate()


def test_torso_tables_match_direct_evaluation(scene, robot) -> None:
    from services.planner.sdf import SignedDistanceField

    sdf = SignedDistanceField(scene, resolution=0.05)
    direct = StateCost(robot, sdf, CostConfig(torso_table_step=0.0))
    tabled = StateCost(robot, sdf, CostConfig(torso_table_step=0.001))
    grid = scene.grid
    rng = np.random.default_rng(1)
    occ = rng.uniform(0, 1, grid.dims).astype(np.float32)
    for c in (direct, tabled):
        c.set_occupancy(occ, grid.origin, grid.resolution)
    g = torch.Generator().manual_seed(1)
    q = robot.lower + (robot.upper - robot.lower) * torch.rand(64, 8, generator=g)
    a, b = direct(q), tabled(q)
    assert torch.allclose(a[:, 0], b[:, 0], atol=1e-3)  # static obstacles: smooth in the lift
    assert torch.allclose(a[:, 1], b[:, 1], rtol=2e-3, atol=2e-3)  # random occupancy: piecewise linear
    centers = robot.sphere_centers(q)
    assert torch.allclose(direct.obstacle(centers) * direct.config.w_obstacle, a[:, 0], atol=1e-5)


def test_waypoint_times_are_the_executed_time_of_the_path() -> None:
    """The executor spends the plan's one dt on every segment: bunched waypoints are slow, and the cost says so.

    Weighting each waypoint by its own segments at the velocity limits charged 0.21 s in a band the executed robot
    spent 1.06 s in (a review script: the same path, waypoints bunched inside the band)."""
    inv_vmax = torch.tensor([1.0, 2.0], dtype=torch.float64)  # joint 1 is twice as slow
    # 5 waypoints: three bunched (0.01 apart) then two long segments (0.4 on joint 0, 0.3 on joint 1 = 0.6 s)
    q = torch.tensor([[0.0, 0.0], [0.01, 0.0], [0.02, 0.0], [0.42, 0.0], [0.42, 0.3]], dtype=torch.float64)
    dt = path_dt(q, inv_vmax, min_dt=0.01)
    assert float(dt) == pytest.approx(0.6)                   # the slowest segment: 0.3 rad at 0.5 rad/s
    w = waypoint_times(q, inv_vmax)
    assert torch.allclose(w, torch.tensor([0.3, 0.6, 0.6, 0.6, 0.3], dtype=torch.float64))
    assert float(w.sum()) == pytest.approx(4 * float(dt))     # (T - 1) dt: the whole executed duration
    # without the plan's min_dt floor: a held path costs no time (its dwell is the planner's), a short one its own
    held = torch.zeros(7, 2, dtype=torch.float64)
    assert float(path_dt(held, inv_vmax, 0.01)) == 0.01 and float(waypoint_times(held, inv_vmax).sum()) == 0.0
    short = q * 0.001
    assert float(waypoint_times(short, inv_vmax).sum()) == pytest.approx(4 * 0.0006)
    batch = torch.stack([q, q * 0.5, q.flip(0)])[None]         # (1, 3, T, D): batched equals looped
    looped = torch.stack([waypoint_times(b, inv_vmax) for b in batch[0]])
    assert torch.equal(waypoint_times(batch, inv_vmax)[0], looped)
