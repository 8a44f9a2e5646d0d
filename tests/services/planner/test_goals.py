"""Goals: grasp poses at the cups -> goal configurations by IK; bad goals dropped with a reason."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from services.planner.costs import StateCost
from services.planner.goals import cup_goals, joint_goals, pose_goals
from services.planner.grasps import GraspConfig, grasp_candidates
from shared.robot import RobotModelError
from shared.scene import Cup


@pytest.fixture(scope="module")
def cost(scene, robot):
    return StateCost.from_scene(scene, robot)


@pytest.fixture(scope="module")
def goals(scene, robot, cost):
    return cup_goals(scene, robot, cost)


def test_both_cups_are_reachable(goals, robot, cost, scene) -> None:
    assert goals.names == ["blue_cup", "red_cup"]
    assert goals.valid.tolist() == [True, True], goals.reasons
    assert goals.q.shape == (2, 8)
    assert bool(robot.within_limits(goals.q).all())
    assert bool(cost.collision_free(goals.q).all())
    assert np.all(goals.clearance >= 0)
    assert torch.allclose(goals.q[:, 0], robot.q_start[0].expand(2))  # torso held at the scene's lift
    for i, name in enumerate(goals.names):
        got = robot.end_effector(goals.q[i]).double().numpy()
        target = goals.poses[i]
        assert np.linalg.norm(got[:3, 3] - target[:3, 3]) < 3e-3
        assert np.linalg.norm(got[:3, :3] - target[:3, :3]) < 0.05
        # the tool point is next to its cup: standoff + radius from the axis (side) or above the rim (top)
        cup = scene.cup(name)
        assert np.linalg.norm(got[:2, 3] - cup.position[:2]) < cup.radius + 0.05 + 0.02


def test_grasp_candidates_geometry(scene) -> None:
    cup = scene.cup("red_cup")
    cfg = GraspConfig(approach="any", pitch_deg=(0.0,), standoff=0.05)
    cands = grasp_candidates(cup, np.array([0.9, -0.35, 1.03]), cfg)
    assert len(cands) == 2 * len(cfg.yaw_offsets_deg)
    for label, t in cands:
        r = t[:3, :3]
        assert np.allclose(r.T @ r, np.eye(3), atol=1e-9) and np.linalg.det(r) == pytest.approx(1.0)
        if label.startswith("side"):
            assert np.linalg.norm(t[:2, 3] - cup.position[:2]) == pytest.approx(cup.radius + 0.05)
            assert abs(r[2, 0]) < 1e-9 and r[2, 2] > 0.99  # horizontal approach, fingers open horizontally
            # the approach axis points at the cup
            to_cup = cup.position[:2] - t[:2, 3]
            assert np.dot(to_cup / np.linalg.norm(to_cup), r[:2, 0]) > 0.99
        else:
            assert r[2, 0] == pytest.approx(-1.0)
            assert t[2, 3] == pytest.approx(cup.position[2] + cup.height + 0.05)


def test_cup_outside_the_workspace_is_dropped(scene, robot, cost) -> None:
    far = Cup("far_cup", np.array([5.0, 5.0, 0.7]), 0.04, 0.1)
    s2 = dataclasses.replace(scene, cups=(scene.cup("red_cup"), far))
    g = cup_goals(s2, robot, cost, config=GraspConfig(pitch_deg=(0.0,), approach="side"))
    assert g.valid.tolist() == [True, False]
    assert "outside the workspace" in g.reasons[1]
    assert bool(robot.within_limits(g.q).all())


def test_cup_beyond_reach_is_dropped(scene, robot, cost) -> None:
    far = Cup("far_cup", np.array([-1.5, -2.5, 0.7]), 0.04, 0.1)  # inside the workspace, 3 m away
    s2 = dataclasses.replace(scene, cups=(far,))
    g = cup_goals(s2, robot, cost)
    assert g.valid.tolist() == [False]
    assert "from the shoulder" in g.reasons[0]


def test_unreachable_pose_reports_ik_failure(robot, cost, scene) -> None:
    # within max_reach but pointing the gripper back at the robot's own shoulder from behind
    t = np.eye(4)
    t[:3, :3] = np.diag([-1.0, -1.0, 1.0])
    t[:3, 3] = robot.fk_links(robot.q_start)[2, :3, 3].double().numpy() + np.array([0.0, 0.0, -0.9])
    g = pose_goals(["impossible"], [[("under the shoulder", t)]], robot, cost, robot.q_start, scene,
                   GraspConfig(n_seeds=4, max_iterations=30))
    assert g.valid.tolist() == [False]
    assert "IK failed" in g.reasons[0] or "collision" in g.reasons[0]
    assert bool(robot.within_limits(g.q).all())


def test_start_outside_limits_is_an_error(scene, robot, cost) -> None:
    bad = robot.q_start.clone()
    bad[4] = 0.5  # elbow flex upper limit is 0
    with pytest.raises(RobotModelError, match="r_elbow_flex_joint"):
        cup_goals(scene, robot, cost, q_start=bad)


def test_joint_goals(robot, cost) -> None:
    ok = robot.q_start.numpy()
    outside = ok.copy()
    outside[4] = 0.5
    nan = ok.copy()
    nan[2] = np.nan
    in_table = ok.copy()
    in_table[1:] = [0.3, 1.0, 0.0, -0.3, 0.0, -0.3, 0.0]
    g = joint_goals(["ok", "outside", "nan", "table"], np.stack([ok, outside, nan, in_table]), robot, cost)
    assert g.valid.tolist() == [True, False, False, False]
    assert g.reasons[1] == "outside the joint limits" and g.reasons[2] == "non-finite joint values"
    assert g.reasons[3] == "goal configuration in collision"
    assert bool(robot.within_limits(g.q).all()) and bool(torch.isfinite(g.q).all())
    with pytest.raises(ValueError, match="joint-space goals"):
        joint_goals(["a"], np.zeros((1, 7)), robot)
