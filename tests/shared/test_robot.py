"""PR2 model: fused FK vs pytorch-kinematics, URDF vs the reference PR2, spheres, limits, IK."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import pytorch_kinematics as pk
import torch

from shared.robot import JOINT_NAMES, PR2, TOOL_FRAME, RobotModelError
from shared.scene import load_scene


@pytest.fixture(scope="module")
def robot() -> PR2:
    return PR2.from_scene(load_scene())


def _random_q(robot: PR2, n: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return robot.lower + (robot.upper - robot.lower) * torch.rand(n, robot.dof, generator=g)


def test_joint_names_limits_and_continuous_range(robot: PR2) -> None:
    assert robot.joint_names == list(JOINT_NAMES)
    assert robot.lower.shape == robot.upper.shape == robot.velocity_limits.shape == (8,)
    assert torch.all(robot.lower < robot.upper)
    assert torch.all(torch.isfinite(robot.lower)) and torch.all(torch.isfinite(robot.upper))
    for name in ("r_forearm_roll_joint", "r_wrist_roll_joint"):
        i = robot.joint_names.index(name)
        assert robot.lower[i] == pytest.approx(-math.pi) and robot.upper[i] == pytest.approx(math.pi)
    assert robot.upper[0] == pytest.approx(0.33)


def test_fused_fk_equals_pytorch_kinematics(robot: PR2) -> None:
    q = _random_q(robot, 500, seed=1)
    fused = robot.fk_links(q)
    ref = robot.fk_reference(q)
    assert fused.shape == (500, len(robot.link_names), 4, 4)
    assert (fused[..., :3, 3] - ref[..., :3, 3]).abs().max() < 1e-5
    assert (fused[..., :3, :3] - ref[..., :3, :3]).abs().max() < 1e-5


def test_fk_batched_equals_looped_and_shapes(robot: PR2) -> None:
    q = _random_q(robot, 2 * 3 * 4, seed=2).reshape(2, 3, 4, 8)
    batched = robot.sphere_centers(q)
    assert batched.shape == (2, 3, 4, len(robot.sphere_links), 3)
    looped = torch.stack([robot.sphere_centers(qi) for qi in q.reshape(-1, 8)]).reshape(batched.shape)
    assert torch.allclose(batched, looped, atol=1e-6)
    ee = robot.end_effector(q)
    assert ee.shape == (2, 3, 4, 4, 4)
    assert torch.allclose(ee, robot.fk_links(q)[..., -1, :, :])


def test_sphere_centres_follow_their_links(robot: PR2) -> None:
    q = _random_q(robot, 64, seed=3)
    centres = robot.sphere_centers(q)
    t = robot.fk_reference(q)[:, robot.sphere_anchor]  # (B, S, 4, 4)
    expect = torch.einsum("bsij,sj->bsi", t[..., :3, :3], robot.spheres.local) + t[..., :3, 3]
    assert (centres - expect).abs().max() < 1e-5


def test_spheres_cover_every_link(robot: PR2) -> None:
    needed = ["base_footprint", "torso_lift_link", "head_tilt_link", "r_shoulder_pan_link", "r_upper_arm_link",
              "r_forearm_link", "r_wrist_flex_link", "r_gripper_palm_link", "r_gripper_l_finger_tip_link",
              "l_upper_arm_link", "l_forearm_link", "l_gripper_palm_link"]
    for link in needed:
        assert link in robot.sphere_links, link
    # the arm is covered along its length: upper arm (0.4 m) and forearm (0.321 m) have no gap > 2 radii
    q = torch.zeros(1, 8)
    c = robot.sphere_centers(q)[0]
    r = robot.sphere_radii
    tool = robot.end_effector(q)[0, :3, 3]
    shoulder = robot.fk_links(q)[0, 2, :3, 3]
    for s in torch.linspace(0, 0.9, 40):  # shoulder pan axis to the palm (the open fingers end at ~0.98)
        p = shoulder + s * (tool - shoulder)  # the arm is straight at q = 0
        assert ((c - p).norm(dim=-1) - r).min() < 0.0, f"gap at {s:.2f} of the arm"


def test_base_transform_places_the_robot() -> None:
    scene = load_scene()
    placed = PR2.from_scene(scene)
    at_origin = PR2()
    q = torch.zeros(3, 8)
    t = torch.tensor(scene.robot.base_transform(), dtype=torch.float32)
    a = placed.fk_links(q)
    b = t @ at_origin.fk_links(q)
    assert torch.allclose(a, b, atol=1e-5)
    # shoulder pan joint height = 0.051 + 0.739675 + torso lift
    z = placed.fk_links(torch.tensor([[0.2] + [0.0] * 7]))[0, 2, 2, 3]
    assert float(z) == pytest.approx(0.051 + 0.739675 + 0.2, abs=1e-5)


def test_start_configuration_is_in_limits_and_collision_free(robot: PR2) -> None:
    assert robot.q_start is not None
    assert bool(robot.within_limits(robot.q_start))
    assert robot.q_start[0] == pytest.approx(load_scene().robot.torso_lift)
    d = robot.self_collision_distance(robot.sphere_centers(robot.q_start))
    assert float(d.min()) > 0.0


def test_validate_configuration_errors(robot: PR2) -> None:
    with pytest.raises(RobotModelError, match="r_elbow_flex_joint"):
        robot.validate_configuration([0.1, 0, 0, 0, 0.5, 0, -0.5, 0])
    with pytest.raises(RobotModelError, match="expected 8"):
        robot.validate_configuration([0.0] * 7)
    with pytest.raises(RobotModelError, match="non-finite"):
        robot.validate_configuration([float("nan")] + [0.0] * 7)
    with pytest.raises(RobotModelError, match="last dimension 8"):
        robot.fk_links(torch.zeros(3, 7))


def test_ik_reaches_a_reachable_pose_and_stays_in_limits(robot: PR2) -> None:
    q_true = torch.tensor([robot.q_start[0].item(), -0.5, 0.3, -1.0, -1.2, 0.5, -0.8, 0.3])
    target = robot.end_effector(q_true).double().numpy()
    q, ok = robot.ik(target, robot.q_start, n_seeds=8)
    assert ok
    assert bool(robot.within_limits(q))
    assert q[0] == pytest.approx(float(robot.q_start[0]))  # torso held
    got = robot.end_effector(q).double().numpy()
    assert np.linalg.norm(got[:3, 3] - target[:3, 3]) < 3e-3


def test_ik_unreachable_reports_failure(robot: PR2) -> None:
    target = np.eye(4)
    target[:3, 3] = [5.0, 5.0, 1.0]
    q, ok = robot.ik(target, robot.q_start, n_seeds=4, max_iterations=30)
    assert not ok
    assert bool(robot.within_limits(q))


def _reference_chain(reference_dir) -> pk.SerialChain:
    root = ET.parse(reference_dir / "pr2.urdf").getroot()
    for tag in ("transmission", "gazebo"):  # pytorch-kinematics' parser rejects PR2 transmissions
        for e in root.findall(tag):
            root.remove(e)
    full = pk.build_chain_from_urdf(ET.tostring(root))
    return pk.SerialChain(full, TOOL_FRAME, "base_footprint")


def test_fk_matches_reference_urdf(reference_dir) -> None:
    ref = _reference_chain(reference_dir)
    assert ref.get_joint_parameter_names() == list(JOINT_NAMES)
    ours = PR2()
    q = _random_q(ours, 1000, seed=7)
    t_ours = ours.chain.forward_kinematics_tensor(q)
    t_ref = ref.forward_kinematics_tensor(q)
    frames = ref.get_frame_names(exclude_fixed=False)
    assert set(frames) <= set(ours.chain.get_frame_names(exclude_fixed=False))
    for name in frames:
        err = (t_ours[ours.chain.frame_to_idx[name], :, :3, 3] - t_ref[ref.frame_to_idx[name], :, :3, 3]).norm(dim=-1)
        assert float(err.max()) <= 1e-3, f"{name}: {float(err.max())} m"
    # the fused kernel against the reference file too
    fused = ours.fk_links(q)
    for i, name in enumerate(ours.link_names):
        err = (fused[:, i, :3, 3] - t_ref[ref.frame_to_idx[name], :, :3, 3]).norm(dim=-1)
        assert float(err.max()) <= 1e-3, f"fused {name}: {float(err.max())} m"


def _joints(path) -> dict[str, ET.Element]:
    return {j.get("name"): j for j in ET.parse(path).getroot().findall("joint")}


def _floats(s: str | None) -> list[float]:
    return [float(v) for v in (s or "0 0 0").split()]


def test_joint_definitions_match_reference(reference_dir) -> None:
    from importlib import resources

    ours = _joints(resources.files("shared") / "data" / "robot" / "pr2.urdf")
    ref = _joints(reference_dir / "pr2.urdf")
    checked = 0
    for name, j in ours.items():
        assert name in ref, f"{name} not in the reference PR2"
        r = ref[name]
        assert j.get("type") == r.get("type"), name
        assert j.find("parent").get("link") == r.find("parent").get("link"), name
        assert j.find("child").get("link") == r.find("child").get("link"), name
        for attr in ("xyz", "rpy"):
            a = _floats(j.find("origin").get(attr)) if j.find("origin") is not None else [0, 0, 0]
            b = _floats(r.find("origin").get(attr)) if r.find("origin") is not None else [0, 0, 0]
            assert np.allclose(a, b, atol=1e-9), f"{name} origin {attr}: {a} != {b}"
        if j.get("type") != "fixed":
            assert np.allclose(_floats(j.find("axis").get("xyz")), _floats(r.find("axis").get("xyz"))), name
            lj, lr = j.find("limit"), r.find("limit")
            for attr in ("lower", "upper", "velocity", "effort"):
                if lr.get(attr) is not None or lj.get(attr) is not None:
                    assert float(lj.get(attr)) == pytest.approx(float(lr.get(attr))), f"{name} limit {attr}"
        checked += 1
    for name in JOINT_NAMES:
        assert name in ours
    assert checked >= 30


def test_float64_model() -> None:
    robot = PR2(dtype=torch.float64)
    q = _random_q(robot, 10, seed=4)
    assert q.dtype == torch.float64
    assert robot.sphere_centers(q).dtype == torch.float64
    assert (robot.fk_links(q) - robot.fk_reference(q)).abs().max() < 1e-10
