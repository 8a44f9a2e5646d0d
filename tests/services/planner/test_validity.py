"""A path into the table or the robot itself is never published: penetration measured densely, beyond the start."""

from __future__ import annotations

import logging
import math
import re

import numpy as np
import pytest
import torch

from services.planner import validity
from services.planner.config import StompConfig
from services.planner.core import GoalSet, Planner, PlannerConfig
from services.planner.costs import StateCost
from services.planner.inputs import PlannerError
from services.planner.multigoal import resample_path
from services.planner.validity import TOLERANCE_M, first_contact, path_penetration, publishable

UNDER_TABLE = [0.237, -0.4594, 0.9945, -2.9553, -1.0481, 2.0756, -2.1326, 1.8017]
"""A free configuration with the gripper under the table's edge (tool at x 0.57, y -0.45, z 0.47 m), drawn at
random by a review: 10 STOMP iterations from the start left 36 of 400 samples of its path inside the table, 2.8 cm
deep, and the Plan said valid."""

BESIDE = [0.237, -1.2221, 1.2027, -1.8983, -0.9774, 0.1022, -1.075, -0.2438]
"""Another free configuration near the table (tool at z 0.52 m) whose 10-iteration path stays free."""


@pytest.fixture(scope="module")
def cost(scene, robot) -> StateCost:
    return StateCost.from_scene(scene, robot)


def _line(robot, goal: list[float], n: int = 40) -> torch.Tensor:
    q0 = robot.q_start
    return q0 + torch.linspace(0, 1, n, dtype=q0.dtype)[:, None] * (torch.tensor(goal, dtype=q0.dtype) - q0)


def test_a_path_through_the_table_is_measured_between_its_waypoints(robot, cost) -> None:
    line = _line(robot, UNDER_TABLE)
    dense = resample_path(line, 2000)
    assert bool(cost.collision_free(line[[0, -1]]).all()) and not bool(cost.collision_free(dense).all())
    deepest = float((cost.radii - cost.sdf(robot.sphere_centers(dense)[..., cost.spheres, :])).amax())
    depth = path_penetration(cost, line[None])
    assert float(depth[0]) == pytest.approx(deepest, abs=0.01)  # the densest check within a centimetre
    # 3 waypoints: every sphere jumps between them; the substeps still find the table
    assert float(path_penetration(cost, _line(robot, UNDER_TABLE, 3)[None])[0]) > 0.5 * deepest
    assert path_penetration(cost, _line(robot, robot.q_start.tolist())[None]).tolist() == [0.0]  # holding still


def test_a_start_inside_the_scene_refuses_only_a_deeper_path(robot, cost) -> None:
    """A real robot read a millimetre inside a modelled table would otherwise have every plan refused."""
    line = _line(robot, UNDER_TABLE)
    dense = resample_path(line, 400)
    depths = (cost.radii - cost.sdf(robot.sphere_centers(dense)[..., cost.spheres, :])).amax(-1)
    inside = int(torch.argmax(depths))  # the deepest configuration of the path
    start = dense[inside]
    assert float(path_penetration(cost, start.expand(5, -1)[None])[0]) == 0.0  # holding where it is
    back = torch.stack([start + (robot.q_start - start) * f for f in torch.linspace(0, 1, 20, dtype=start.dtype)])
    assert float(path_penetration(cost, back[None])[0]) < TOLERANCE_M  # leaving the table
    assert float(path_penetration(cost, dense[None])[0]) > 0  # from outside, into it


def test_only_free_paths_are_published_and_with_none_free_every_finite_one_is(robot, cost, caplog) -> None:
    paths = torch.stack([_line(robot, UNDER_TABLE), _line(robot, robot.q_start.tolist())])  # into the table; still
    terms = {n: torch.ones(2, dtype=paths.dtype) for n in ("smoothness", "obstacle", "human", "total")}
    free, depth = publishable(cost, paths, terms)
    assert free.tolist() == [False, True] and depth[0] > 0.01 and depth[1] == 0.0
    terms["total"] = torch.tensor([1.0, float("nan")], dtype=paths.dtype)  # the free one's cost not finite
    with caplog.at_level(logging.WARNING, logger="foresight.planner"):
        free, depth = publishable(cost, paths, terms)
    assert free.tolist() == [True, False] and depth[0] == 0.0  # none free: the finite ones, as optimised, and said
    assert any(re.search(r"every path passes into the scene or the robot this step \(the least by \d+\.\d cm, from "
                         r"\d+% of the way\); published as optimised", r.getMessage()) for r in caplog.records)
    terms["total"] = torch.full((2,), float("nan"), dtype=paths.dtype)
    with pytest.raises(PlannerError, match="no goal has a finite cost this step"):
        publishable(cost, paths, terms)


def test_the_warning_says_where_along_the_path_it_first_goes_in(robot, cost, caplog, monkeypatch) -> None:
    """Real time's first plans went 1-8.5 cm into the table 2-6 s along paths the robot follows for ~0.1 s before
    the next plan: the warning said how deep, not where, which is what tells a user whether the robot goes there."""
    line = _line(robot, UNDER_TABLE)  # 40 waypoints
    dense = resample_path(line, 2000)
    depth = (cost.radii - cost.sdf(robot.sphere_centers(dense)[..., cost.spheres, :])).amax(-1).clamp(min=0)
    truth = int(torch.nonzero(depth - depth[0] >= TOLERANCE_M).flatten()[0]) / 1999
    at = first_contact(cost, line)
    assert 0.05 < at < 0.95 and at == pytest.approx(truth, abs=1 / 39)  # within a waypoint of the densest check
    assert math.isnan(first_contact(cost, _line(robot, robot.q_start.tolist())))  # holding still: never
    terms = {n: torch.ones(1, dtype=line.dtype) for n in ("smoothness", "obstacle", "human", "total")}
    monkeypatch.setattr(validity, "_said", [-math.inf])  # a warning a second at most: the test's own
    with caplog.at_level(logging.WARNING, logger="foresight.planner"):
        publishable(cost, line[None], terms, torch.tensor([0.1], dtype=line.dtype))
    assert f"from {at * 39 * 0.1:.2f} s into its 3.90 s)" in caplog.text


def test_the_planner_never_publishes_a_path_into_the_table(scene, robot, cost) -> None:
    """The review's case: 10 iterations (real time's anytime minimum) towards a goal under the table's edge."""
    cfg = PlannerConfig(compile=False, stomp=StompConfig(iterations=10))
    names = ["under_table", "beside"]
    goals = GoalSet.joint_space(names, np.array([UNDER_TABLE, BESIDE]), robot)
    planner = Planner(scene, cfg, robot=robot, cost=cost, goals=goals)
    result = planner.step(robot.q_start.numpy(), np.zeros(scene.grid.dims, np.float32))
    for k in range(2):
        dense = resample_path(torch.as_tensor(result.trajectories[k], dtype=robot.dtype), 400)
        collides = not bool(cost.collision_free(dense).all())
        assert not (result.valid[k] and collides), names[k]
    assert result.valid.tolist() == [False, True] and result.chosen == 1
    assert result.reasons[0].startswith("its path passes ") and "cm into the scene or the robot" in result.reasons[0]
    alone = Planner(scene, cfg, robot=robot, cost=cost, goals=GoalSet.joint_space(names[:1], np.array([UNDER_TABLE]),
                                                                                   robot))
    only = alone.step(robot.q_start.numpy(), np.zeros(scene.grid.dims, np.float32))  # the one goal: published, said
    assert only.valid.tolist() == [True] and only.chosen == 0


def test_the_paper_protocol_keeps_the_authors_goal_choice_without_the_check(scene, robot, cost) -> None:
    """The authors' goal choice sets no colliding path aside: their protocol turns the product's check off."""
    from services.experiments.protocol import PAPER, PRODUCT

    assert PAPER.free_paths is False and PRODUCT.free_paths is True
    cfg = PlannerConfig(compile=False, stomp=StompConfig(iterations=10), free_paths=False)
    goals = GoalSet.joint_space(["under_table", "beside"], np.array([UNDER_TABLE, BESIDE]), robot)
    result = Planner(scene, cfg, robot=robot, cost=cost, goals=goals).step(robot.q_start.numpy(),
                                                                           np.zeros(scene.grid.dims, np.float32))
    assert result.valid.tolist() == [True, True]
