"""The body term (``services.planner.body``): the planner keeps clear of the person as last seen (real time)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from services.executor.config import SeparationConfig
from services.planner.bench import blob_occupancy
from services.planner.body import BodyCapsules, PersonBody, body_clearances
from services.planner.config import PlannerServiceConfig
from services.planner.core import GoalSet, Planner, PlannerConfig
from services.planner.costs import CostConfig, CostInputError, StateCost
from services.planner.fused import FusedCost
from services.planner.stomp import StompConfig
from shared.clearance import sphere_capsule_clearance
from shared.config import ConfigError
from shared.human import HumanModel, StreamPlacement
from shared.robot import PR2
from shared.synthetic import generate_library

STOP_M = SeparationConfig().stop_m  # the guard's distance (0.05 m)


def _poses() -> np.ndarray:
    """``(n, 12)`` recorder-frame poses of a synthetic demonstration."""
    return generate_library(seed=0).demos[0].features.astype(np.float64)


def _capsules(scene) -> tuple[np.ndarray, np.ndarray]:
    """The human model's capsules of a demonstration's first pose, where the scene places the person."""
    return HumanModel().capsules(StreamPlacement(scene).place(0, 0, _poses()[0]))


def test_each_sphere_s_clearance_is_the_shared_measure(robot, scene) -> None:
    """Per sphere, the smallest over the capsules of ``shared.clearance``'s measure (the guard's); batched = looped."""
    ends, radii = _capsules(scene)
    body = BodyCapsules.build(ends, radii, "cpu", torch.float64)
    rng = np.random.default_rng(0)
    centres = torch.as_tensor(ends.reshape(-1, 3).mean(0) + rng.uniform(-0.4, 0.4, (4, 6, 3)))  # around the body
    r = torch.as_tensor(rng.uniform(0.02, 0.13, 6))
    got = body_clearances(centres.permute(2, 1, 0), r, body)  # (6, 4): the kernel's layout, the batch last
    assert got.shape == (6, 4)
    for n in range(4):
        for s in range(6):
            want = sphere_capsule_clearance(centres[n, s:s + 1].numpy(), r[s:s + 1].numpy(), ends, radii)
            assert float(got[s, n]) == pytest.approx(float(want), abs=1e-9)
            one = body_clearances(centres[n, s:s + 1].t(), r[s:s + 1], body)  # (1,): no batch axis
            assert one.shape == (1,) and float(one[0]) == pytest.approx(float(got[s, n]))
    assert float(got.min()) < 0 < float(got.max())  # spheres inside the body and clear of it


def test_bad_capsules_are_named(robot, scene) -> None:
    cost = StateCost.from_scene(scene, robot)
    ends, radii = _capsules(scene)
    with pytest.raises(CostInputError, match=r"ends \(C, 2, 3\) and radii \(C,\)"):
        cost.set_body(ends[:, 0], radii)
    ends[2, 1, 0] = np.nan
    with pytest.raises(CostInputError, match="NaN or inf"):
        cost.set_body(ends, radii)
    assert cost.body is None
    with pytest.raises(ConfigError, match="planner.cost.body_clearance"):
        PlannerConfig(cost=CostConfig(body_clearance=-0.1)).validate()


def test_the_body_term_is_real_time_s() -> None:
    """Lock-step runs measure the paper's planners: the service's planner there has no body term."""
    assert PlannerServiceConfig(mode="lockstep").planner_config().cost.body_clearance == 0.0
    assert PlannerServiceConfig(mode="realtime").planner_config().cost.body_clearance == CostConfig().body_clearance > 0


@pytest.mark.parametrize("pointwise", [False, True])
def test_the_fused_kernel_equals_the_reference_with_a_body(scene, pointwise: bool) -> None:
    """float64, the person placed by the scene and moved onto the robot: the obstacle term carries the body's hinge."""
    robot = PR2.from_scene(scene, dtype=torch.float64)
    cost = StateCost.from_scene(scene, robot, CostConfig())
    goals = GoalSet.joint_space(["start"], robot.q_start[None], robot)
    planner = Planner(scene, PlannerConfig(dtype="float64", compile=False, stomp=StompConfig(iterations=1)),
                      robot=robot, cost=cost, goals=goals)
    assert planner.fused is not None
    fused = FusedCost(robot, cost, planner.w_smooth, robot.velocity_limits * planner.config.velocity_scale, True,
                      grid=scene.grid, pointwise=pointwise, dwell=planner.config.goal_dwell_s)
    ends, radii = _capsules(scene)
    hand = robot.sphere_centers(robot.q_start)[robot.arm_carried_slice].double().numpy().mean(0)
    ends = ends - ends.reshape(-1, 3).mean(0) + hand  # the body where the arm is
    g = torch.Generator().manual_seed(3)
    q = (robot.q_start + 0.4 * torch.randn(4, 6, 40, 8, generator=g, dtype=torch.float64)).clamp(robot.lower,
                                                                                                robot.upper)
    cost.set_occupancy(blob_occupancy(scene), scene.grid.origin, scene.grid.resolution)
    without = planner.waypoint_cost_reference(q)
    cost.set_body(ends, radii)
    ref, out = planner.waypoint_cost_reference(q), fused(q)
    assert float((ref - without).min()) >= 0 and float((ref - without).max()) > 1.0  # the body term is there
    assert torch.allclose(out, ref, rtol=1e-9, atol=1e-9), float((out - ref).abs().max())


def test_without_a_body_the_term_adds_nothing(scene) -> None:
    """No pose yet (the kernel's capsules far away) gives bit for bit the costs of ``body_clearance = 0``."""
    robot = PR2.from_scene(scene)
    q = (robot.q_start + 0.5 * torch.randn(3, 5, 40, 8, generator=torch.Generator().manual_seed(1))).clamp(
        robot.lower, robot.upper)
    out = []
    for eps in (0.10, 0.0):
        cost = StateCost.from_scene(scene, robot, CostConfig(body_clearance=eps))
        cost.set_occupancy(blob_occupancy(scene), scene.grid.origin, scene.grid.resolution)
        fused = FusedCost(robot, cost, 10.0, robot.velocity_limits * 0.5, True, grid=scene.grid)
        out.append((fused(q), cost(q)))
    assert torch.equal(out[0][0], out[1][0]) and torch.equal(out[0][1], out[1][1])


def _clearances(robot: PR2, traj: torch.Tensor, body: BodyCapsules) -> list[float]:
    """The arm's clearance to ``body`` at each waypoint of ``traj`` ``(T, D)`` (m)."""
    arm = robot.sphere_centers(traj)[:, robot.arm_carried_slice].permute(2, 1, 0)  # (3, A, T)
    return body_clearances(arm, robot.sphere_radii[robot.arm_carried_slice], body).amin(0).tolist()


@pytest.fixture(scope="module")
def hand_beside(scene):
    """A goal whose plan, made without the body term, passes within the guard's ``stop_m`` of a hand held beside its
    way (level with the path's middle), the path's ends clear of it.

    Returns ``(planner, its cost, the free path (T, D), the hand's capsule ends (1, 2, 3) and radius (1,))``; the
    planner plans for that goal alone, its cost holds no body.
    """
    robot = PR2.from_scene(scene)
    config = PlannerConfig(compile=False, stomp=StompConfig(iterations=50))
    base = Planner(scene, config, robot=robot)
    radius = np.array([0.05])  # the human model's hand
    for (k, name), side in itertools.product(enumerate(base.goals.names), (0.15, -0.15, 0.1, -0.1)):
        planner = Planner(scene, config, robot=robot, cost=base.cost,
                          goals=GoalSet.joint_space([name], base.goals.q[k:k + 1], robot))
        free = planner.step(robot.q_start.numpy(), _empty(scene))
        traj = torch.as_tensor(free.trajectories[free.chosen], dtype=robot.dtype)
        hand = robot.sphere_centers(traj)[:, robot.arm_carried_slice][:, -6:].mean(1).double().numpy()  # (T, 3)
        mid = len(traj) // 2
        across = np.cross(hand[mid + 1] - hand[mid - 1], [0.0, 0.0, 1.0])
        held = hand[mid] + side * across / np.linalg.norm(across)
        ends = np.stack([held - [0.0, 0.0, 0.03], held + [0.0, 0.0, 0.03]])[None]  # (1, 2, 3)
        along = _clearances(robot, traj, BodyCapsules.build(ends, radius, "cpu", robot.dtype))
        if min(along) < STOP_M and min(along[0], along[-1]) > 0.07:  # held on the way, room at both ends
            return planner, base.cost, traj, ends, radius
    pytest.fail("no goal of the scene passes within stop_m of a hand beside its way with its ends clear")


def _empty(scene) -> np.ndarray:
    """No predicted occupancy: the scene grid's zeros."""
    return np.zeros(scene.grid.dims, dtype=np.float32)


def test_the_plan_keeps_the_guard_s_distance_from_a_hand_held_beside_its_way(scene, hand_beside) -> None:
    """A hand held beside the plan made without it, within the guard's ``stop_m`` of its path: the next plans keep
    more than ``stop_m`` from it all the way (as far as their start and goal allow).

    Without the term the executor's guard held the robot there, and the planner proposed the same path at every step
    again (docs/executor.md). Replanning as in real time from the start, each step warm-started from the last."""
    planner, cost, free, ends, radius = hand_beside
    robot = planner.robot
    planner.reset()
    cost.set_body(ends, radius)
    try:
        for _ in range(3):
            kept = planner.step(free[0].numpy(), _empty(scene))
    finally:
        cost.set_body(None, None)
    traj = torch.as_tensor(kept.trajectories[kept.chosen], dtype=robot.dtype)
    assert min(_clearances(robot, traj, BodyCapsules.build(ends, radius, "cpu", robot.dtype))) > STOP_M


def test_a_robot_held_within_stop_m_gets_a_plan_the_guard_lets_it_follow(scene, hand_beside) -> None:
    """The robot already within ``stop_m`` of the hand (where the plan made without the term took it): planned from
    there, each step keeps or widens its clearance while within ``stop_m``, so the guard takes every step; the plan
    made without the term closes in and would be held at once."""
    planner, cost, free, ends, radius = hand_beside
    robot = planner.robot
    body = BodyCapsules.build(ends, radius, "cpu", robot.dtype)
    along = _clearances(robot, free, body)
    i = next(i for i, c in enumerate(along) if c < STOP_M)  # where the guard first stops it
    held = free[i].numpy()

    def closing_steps(with_term: bool) -> list[tuple[float, float]]:
        """The plan's steps within stop_m that shrink its clearance (the guard refuses them)."""
        planner.reset()
        cost.set_body(*((ends, radius) if with_term else (None, None)))
        try:
            plan = planner.step(held, _empty(scene))
        finally:
            cost.set_body(None, None)
        c = _clearances(robot, torch.as_tensor(plan.trajectories[plan.chosen], dtype=robot.dtype), body)
        return [(a, b) for a, b in zip(c[:-1], c[1:], strict=True) if a < STOP_M and b < a - 1e-4]

    assert closing_steps(with_term=False)  # the way on, past the hand: held
    assert closing_steps(with_term=True) == []


def test_the_person_s_body_is_placed_as_the_guard_places_it(scene) -> None:
    """The newest pose's capsules, each demonstration placed from its first pose (``StreamPlacement``)."""
    poses = _poses()
    first, later = poses[0], poses[len(poses) // 2]
    person = PersonBody(scene)
    assert person.capsules() is None
    person.note_pose(3, 0, first, 1.0)
    person.note_pose(3, 1, later, 1.1)
    placement = StreamPlacement(scene)
    placement.place(3, 0, first)
    want = HumanModel().capsules(placement.place(3, 1, later))
    got = person.capsules()
    assert got is not None and person.stamp_ == 1.1
    np.testing.assert_allclose(got[0], want[0])
    np.testing.assert_allclose(got[1], want[1])
    assert float(np.abs(got[0] - HumanModel().capsules(StreamPlacement(scene).place(3, 1, later))[0]).max()) > 0.01
