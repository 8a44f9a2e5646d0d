"""The experiments' measures: the paper's interference and the clearance to the real human."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from services.experiments.measures import (
    contact_summary,
    interference,
    interference_along_path,
    path_samples,
    penetration_per_state,
    postures_at,
    robot_points,
    sphere_surface_offsets,
)
from shared.protocol import HumanPose, OccupancyGrid
from shared.scene import load_scene


class PointRobot:
    """One collision sphere of radius ``r`` whose centre is ``q[:3]``."""

    def __init__(self, r: float = 0.02) -> None:
        self.lower = torch.zeros(3, dtype=torch.float64)
        self.sphere_radii = torch.tensor([r], dtype=torch.float64)

    def sphere_centers(self, q: torch.Tensor) -> torch.Tensor:
        return q[..., None, :3]


def grid_with_block(p: float = 1.0) -> OccupancyGrid:
    """A 20^3 grid of 5 cm voxels from the origin, occupied with ``p`` in x, y, z in [0.4, 0.6)."""
    dense = np.zeros((20, 20, 20), dtype=np.float32)
    dense[8:12, 8:12, 8:12] = p
    return OccupancyGrid.from_dense(dense, origin=np.zeros(3), resolution=0.05, method="prediction", stamp=0.0,
                                    tick=0, tick_last=True, demo_id=0, index=0)


def test_sphere_offsets_cover_the_surface():
    pts = sphere_surface_offsets(0.1, 0.025)
    np.testing.assert_allclose(pts[0], 0.0)
    np.testing.assert_allclose(np.linalg.norm(pts[1:], axis=1), 0.1, atol=1e-12)
    # every direction has a surface point within about one spacing
    rng = np.random.default_rng(0)
    probe = rng.normal(size=(500, 3))
    probe = 0.1 * probe / np.linalg.norm(probe, axis=1, keepdims=True)
    nearest = np.min(np.linalg.norm(probe[:, None] - pts[None, 1:], axis=-1), axis=1)
    assert nearest.max() < 0.025


def test_interference_is_zero_outside_and_grows_with_time_inside():
    robot, occ = PointRobot(), grid_with_block()
    t = np.arange(11) * 0.1
    outside = np.tile([0.1, 0.1, 0.1], (11, 1))
    assert interference(robot, outside, t, occ) == 0.0
    costs = []
    for k in range(0, 11, 2):  # the last k states sit in the middle of the block
        q = outside.copy()
        q[11 - k:] = [0.5, 0.5, 0.5]
        costs.append(interference(robot, q, t, occ))
    assert costs[0] == 0.0
    assert all(b > a for a, b in zip(costs, costs[1:], strict=False))
    # inside, the sphere's points occupy a fixed set of voxels: the cost is linear in the time spent there
    np.testing.assert_allclose(np.diff(costs), costs[1], rtol=1e-9)


def test_path_samples_are_evenly_spaced_along_a_bent_path_checked_by_hand():
    q = np.array([[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.03, 0.04, 0.0]])  # 0.03 then 0.04: length 0.07
    samples, seg = path_samples(q, 0.01)
    assert len(samples) == 7
    np.testing.assert_allclose(samples[2], [0.03, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(samples[4], [0.03, 0.02, 0.0], atol=1e-12)
    assert seg.tolist() == [1, 1, 1, 2, 2, 2, 2]


def test_path_integral_is_zero_outside_grows_with_length_inside_and_ignores_time():
    robot, occ = PointRobot(), grid_with_block()
    outside = np.linspace([0.05, 0.05, 0.05], [0.3, 0.05, 0.05], 11)  # 0.25 long, no occupied voxel near
    assert interference_along_path(robot, outside, occ).sum() == 0.0
    tiny = PointRobot(r=1e-4)  # its points all lie in one voxel of probability 1: cost 1 per sample
    inside = [interference_along_path(tiny, np.linspace([0.405, 0.42, 0.42], [0.405 + length, 0.42, 0.42], 9), occ,
                                      ds=0.005).sum() for length in (0.01, 0.02, 0.03, 0.04)]
    np.testing.assert_allclose(inside, [0.01, 0.02, 0.03, 0.04], atol=1e-12)  # = the length inside, by hand
    # a step counts the mean of its two ends' costs, the authors' cs_integral (a right sum counted the end's whole):
    # from outside the block to 1 mm inside it, only the last sample is in: half a step of cost 1
    entering = np.linspace([0.381, 0.42, 0.42], [0.401, 0.42, 0.42], 5)  # 0.02 long, 4 steps of 0.005
    assert interference_along_path(tiny, entering, occ, ds=0.005).sum() == pytest.approx(0.5 * 0.005)
    leaving = entering[::-1]  # the start inside: half a step too (a right sum counted none)
    assert interference_along_path(tiny, leaving, occ, ds=0.005).sum() == pytest.approx(0.5 * 0.005)
    # standing still accrues nothing (unlike the time integral): a path of length 0
    still = np.tile([0.5, 0.5, 0.5], (20, 1))
    assert interference_along_path(robot, still, occ).sum() == 0.0
    assert interference(robot, still, np.arange(20) * 0.1, occ) > 0.0


def test_a_sphere_reaching_into_the_block_counts_without_its_centre_inside():
    robot, occ = PointRobot(r=0.04), grid_with_block()
    q = np.array([[0.37, 0.5, 0.5]] * 2)  # centre 3 cm outside the block (which starts at x = 0.40)
    assert interference(robot, q, np.array([0.0, 1.0]), occ) > 0
    assert interference(PointRobot(r=0.02), q, np.array([0.0, 1.0]), occ) == 0


def test_penetration_counts_each_voxel_once_whatever_the_sampling():
    robot, occ = PointRobot(r=0.06), grid_with_block(0.5)
    q = np.array([[0.5, 0.5, 0.5]])
    coarse = penetration_per_state(robot_points(robot, q, 0.025), occ)
    pts = robot_points(robot, q, 0.002)
    fine = penetration_per_state(pts, occ)
    assert coarse[0] == pytest.approx(fine[0])
    # brute force: the distinct voxels of the block that the sphere's points fall in, at 128/255 each
    vox = {tuple(v) for v in np.floor(pts[0] / 0.05).astype(int) if all(8 <= c < 12 for c in v)}
    assert fine[0] == pytest.approx(len(vox) * 128 / 255)
    assert len(vox) > 8


def test_contact_summary_integrates_time():
    s = contact_summary(np.array([0.2, 0.04, -0.01, -0.02, 0.3]), np.array([0.0, 0.1, 0.2, 0.4, 0.5]))
    assert s.min_clearance == pytest.approx(-0.02)
    assert s.time_in_contact == pytest.approx(0.3)
    assert s.time_near == pytest.approx(0.4)


def test_postures_follow_the_stream_and_hold_at_the_ends():
    scene = load_scene()
    feats = np.zeros((3, 12))
    feats[:, 0] = [0.0, 0.1, 0.2]
    poses = [HumanPose(stamp=float(i), tick=i, tick_last=True, demo_id=0, index=i, features=feats[i]) for i in range(3)]
    out = postures_at(poses, np.array([-1.0, 0.5, 1.5, 9.0]), scene)
    x0 = scene.human.pelvis_xyz[0]
    c = np.cos(scene.human.pelvis_yaw)
    np.testing.assert_allclose(out[:, 0], x0 + c * np.array([0.0, 0.05, 0.15, 0.2]), atol=1e-12)


def test_culled_interference_equals_every_point_on_the_pr2():
    """Sampling only the spheres that can reach a non-zero voxel gives the same sums as every sphere."""
    from services.experiments.measures import interference_over_time, spheres_near_occupancy
    from shared.robot.pr2 import PR2

    robot = PR2(dtype=torch.float64)
    lo, hi = robot.lower.numpy(), robot.upper.numpy()
    q = lo + (hi - lo) * np.linspace(0.2, 0.8, 12)[:, None]  # (12, D) a sweep through the joint ranges
    centres = robot.sphere_centers(torch.as_tensor(q)).numpy()
    # a blob of probabilities around the arm's reach at mid-sweep, 4 cm voxels
    mid = centres[6].mean(axis=0)
    origin = mid - 0.4
    idx = np.stack(np.meshgrid(*[np.arange(20)] * 3, indexing="ij"), -1)
    d = np.linalg.norm(origin + (idx + 0.5) * 0.04 - mid, axis=-1)
    dense = np.where(d < 0.25, 1.0 - d / 0.25, 0.0).astype(np.float32)
    occ = OccupancyGrid.from_dense(dense, origin=origin, resolution=0.04, method="prediction", stamp=0.0,
                                   tick=0, tick_last=True, demo_id=0, index=0)
    t = np.arange(12) * 0.1
    every = penetration_per_state(robot_points(robot, q, 0.02), occ)
    culled = interference_over_time(robot, q, t, occ)
    np.testing.assert_allclose(culled[1:], every[1:] * 0.1, rtol=1e-12)
    assert every.max() > 0
    near = spheres_near_occupancy(centres, robot.sphere_radii.numpy(), occ)
    assert 0 < near.sum() < near.size  # some spheres are skipped, some are kept
