"""The paper's three scenes: each loads, its start is free, its cups are reachable; they match Move3D's."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from services.planner.costs import CostConfig, StateCost
from services.planner.goals import cup_goals
from shared.robot import PR2
from shared.scene import PAPER_SCENES, SceneError, embedded_scenes, load_scene

REFERENCE = Path(__file__).resolve().parents[3] / "shared" / "reference" / "move3d-scenes"


def test_every_paper_scene_is_embedded_and_loads_by_either_name():
    assert set(PAPER_SCENES.values()) <= set(embedded_scenes())
    for paper, name in PAPER_SCENES.items():
        for spec in (paper, name, paper.lower()):
            scene = load_scene(spec)
            assert scene.name == name and scene.paper_name == paper
            assert load_scene(scene.ref).name == name
    with pytest.raises(SceneError, match="PR2TwoCupsFacing"):
        load_scene("PR2TwoCupsFacin")


@pytest.mark.parametrize("name", sorted(PAPER_SCENES.values()))
def test_start_is_collision_free_and_both_cups_are_reachable(name):
    scene = load_scene(name)
    robot = PR2.from_scene(scene)
    cost = StateCost.from_scene(scene, robot, CostConfig())
    assert bool(cost.collision_free(robot.q_start[None])[0]), "start configuration in collision"
    goals = cup_goals(scene, robot, cost)
    assert goals.names == ["blue_cup", "red_cup"]
    assert bool(goals.valid.all()), goals.reasons
    for i, cup in enumerate(goals.names):
        # every goal puts the gripper within 15 cm of its cup (the paper's goals hover over the cup)
        gap = np.linalg.norm(goals.poses[i][:2, 3] - scene.cup(cup).center[:2])
        assert gap < 0.15, (cup, gap)


def test_scene_goal_configurations_are_used_where_the_scene_gives_them():
    scene = load_scene("pr2_two_cups_facing")
    robot = PR2.from_scene(scene)
    goals = cup_goals(scene, robot, names=["red_cup", "blue_cup"])
    assert goals.labels == ["scene goal configuration"] * 2
    np.testing.assert_allclose(goals.q[0, 1:].double().numpy(), scene.cup("red_cup").goal_arm, atol=1e-6)
    side = load_scene("pr2_two_cups_side")
    g = cup_goals(side, PR2.from_scene(side))
    assert g.labels[1] == "scene goal configuration" and g.labels[0] != "scene goal configuration"


def _sce_pr2(path: Path) -> dict[str, list[float]]:
    """The PR2's configurations in a Move3D .sce file (current, goto, Config__N), in Move3D's dof order."""
    out, robot = {}, None
    for line in path.read_text().splitlines():
        t = line.split()
        if t[:2] == ["p3d_sel_desc_name", "P3D_ROBOT"]:
            robot = t[2]
        elif robot == "PR2_ROBOT" and t and t[0] in ("p3d_set_robot_current", "p3d_set_robot_goto"):
            out[t[0].rsplit("_", 1)[-1]] = [float(x) for x in t[1:]]
        elif robot == "PR2_ROBOT" and t[:1] == ["p3d_set_robot_config"]:
            out[t[1]] = [float(x) for x in t[2:]]
    return out


@pytest.mark.skipif(not REFERENCE.is_dir(), reason="../shared/reference/move3d-scenes is not beside the repository")
@pytest.mark.parametrize("paper", sorted(PAPER_SCENES))
def test_scene_matches_the_move3d_file(paper):
    """Base pose, torso and start arm come from the .sce; FK of its configurations finds its gripper frames."""
    scene = load_scene(paper)
    if not (REFERENCE / f"{paper}.sce").is_file():
        pytest.skip(f"{paper}.sce is not among ../shared/reference/move3d-scenes (see the test below)")
    sce = _sce_pr2(REFERENCE / f"{paper}.sce")
    cur = sce["current"]
    # Move3D dofs: 6-11 base x y z rx ry rz (deg), 12 torso, 16-22 right arm (deg), 37-39 the arm's object frame
    np.testing.assert_allclose(scene.robot.base_xy, cur[6:8], atol=1e-3)
    # pr2_two_cups (written before the other two) rounds the yaw to -165 deg: 0.05 deg, under 1 mm at the gripper
    assert math.degrees(scene.robot.base_yaw) == pytest.approx(cur[11], abs=0.05 if paper == "PR2TwoCups" else 1e-3)
    assert scene.robot.torso_lift == pytest.approx(cur[12], abs=1e-3)
    if paper != "PR2TwoCups":  # pr2_two_cups keeps the project's own start (docs/scenes.md)
        np.testing.assert_allclose(np.degrees(scene.robot.start_arm), cur[16:23], atol=0.01)
    robot = PR2.from_scene(scene)
    for key, vals in sce.items():
        q = torch.tensor([[vals[12], *np.radians(vals[16:23])]], dtype=torch.float32)
        ee = robot.end_effector(q)[0, :3, 3].double().numpy()
        assert np.linalg.norm(ee - np.array(vals[37:40])) < 0.02, (key, ee, vals[37:40])
    goals = {c.name: c.goal_arm for c in scene.cups if c.goal_arm is not None}
    for arm in goals.values():
        assert any(np.allclose(np.degrees(arm), v[16:23], atol=0.01) for k, v in sce.items() if k != "current")


def test_the_authors_table1_scene_matches_its_move3d_file():
    """PR2TwoCupsSideParallel (jmainpri/move3d-assets Gesture/SCENARIOS, 99ace46; not in ../shared): its figures."""
    scene = load_scene("PR2TwoCupsSideParallel")
    np.testing.assert_allclose(scene.robot.base_xy, [0.828, -1.336])
    assert math.degrees(scene.robot.base_yaw) == pytest.approx(151.812) and scene.robot.torso_lift == 0.31
    current = [-19.406, 56.867, -96.504, -102.942, -45.206552, -9.579, 0.0]  # dofs 16-22 of its current
    goto = [-32.874, 15.529, -96.675105, -21.795846, -45.206552, -44.458, 0.0]  # and of its goto (= Config__1)
    np.testing.assert_allclose(np.degrees(scene.robot.start_arm), current, atol=0.01)
    np.testing.assert_allclose(np.degrees(scene.cup("red_cup").goal_arm), goto, atol=0.01)
    np.testing.assert_allclose(scene.cup("blue_cup").position, [0.218, -0.862, 0.635])  # Cup1
    np.testing.assert_allclose(scene.cup("red_cup").position, [0.338, -0.635, 0.635])  # Cup2
    robot = PR2.from_scene(scene)
    for arm, frame in ((current, [0.486253, -1.379493, 0.846423]), (goto, [0.354429, -0.587451, 0.788462])):
        q = torch.tensor([[0.31, *np.radians(arm)]], dtype=torch.float32)
        ee = robot.end_effector(q)[0, :3, 3].double().numpy()
        assert np.linalg.norm(ee - np.array(frame)) < 0.02, (ee, frame)  # the gripper where Move3D put it



@pytest.mark.parametrize("name, match", [("r" * 257, r"cups\[1\].name has 257 characters"),
                                         ("", r"cups\[1\].name has 0 characters")])
def test_a_cup_whose_name_no_plan_could_carry_is_refused(tmp_path, name, match):
    embedded = Path(__file__).resolve().parents[2] / "shared" / "data" / "scenes" / "pr2_two_cups_side.toml"
    text = embedded.read_text()
    assert text.count('name = "red_cup"') == 1  # every cup is a goal whose name goes with every plan
    (tmp_path / "scene.toml").write_text(text.replace('name = "red_cup"', f'name = "{name}"'))
    with pytest.raises(SceneError, match=match):
        load_scene(str(tmp_path / "scene.toml"))
