"""Human model: reference geometry, batched kinematics, body surface, voxels, placement, paper-data check."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shared.human import HumanError, HumanModel, StreamPlacement, place_in_scene, reach_points, voxelize
from shared.scene import Grid, load_scene

REF = {  # herakles-human.macro zero pose, pelvis frame
    "r_shoulder": (-0.011, -0.240, 0.429),
    "r_elbow": (-0.007, -0.446, 0.430),
    "r_wrist": (-0.004, -0.697, 0.435),
}


@pytest.fixture(scope="module")
def model() -> HumanModel:
    return HumanModel()


def random_postures(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    f = rng.normal(size=(n, 12)) * 0.5
    f[:, 0:3] = rng.normal(size=(n, 3)) + [0, 0, 1]
    f[:, 10] = rng.uniform(0.0, 0.2, size=n)
    return f


def test_zero_pose_reference_positions(model: HumanModel) -> None:
    j = model.joint_positions(np.zeros(12))
    for name, ref in REF.items():
        np.testing.assert_allclose(j[model.JOINT_NAMES.index(name)], ref, atol=1.5e-3)
    assert {"pelvis", "r_shoulder", "r_elbow", "r_wrist", "r_hand"} <= set(model.JOINT_NAMES)


def test_joint_conventions(model: HumanModel) -> None:
    names = model.JOINT_NAMES
    sh, el, wr = (names.index(n) for n in ("r_shoulder", "r_elbow", "r_wrist"))
    f = np.zeros(12)
    f[7] = math.pi / 2  # shoulder X +90 deg: the sideways arm hangs down
    j = model.joint_positions(f)
    d = j[wr] - j[sh]
    assert d[2] < -0.4 and abs(d[1]) < 0.02
    f = np.zeros(12)
    f[8] = math.pi / 2  # shoulder Z +90 deg: the arm points forward
    d = model.joint_positions(f)[wr] - model.joint_positions(f)[sh]
    assert d[0] > 0.4
    f = np.zeros(12)
    f[10] = 0.1  # arm translation lengthens the upper arm
    j0, j1 = model.joint_positions(np.zeros(12)), model.joint_positions(f)
    np.testing.assert_allclose(j1[el] - j0[el], [0.0, -0.1, 0.0], atol=1e-12)  # along the zero-pose arm (-y)
    assert np.linalg.norm(j1[el] - j1[sh]) == pytest.approx(np.linalg.norm(j0[el] - j0[sh]) + 0.1, abs=1e-4)
    f = np.zeros(12)
    f[11] = math.pi / 2  # elbow Z +90 deg: the forearm points forward
    d = model.joint_positions(f)[wr] - model.joint_positions(f)[el]
    assert d[0] > 0.2
    f = np.zeros(12)
    f[:4] = [1.0, 2.0, 0.9, math.pi / 2]  # pelvis pose: translate, then yaw (body x -> world y)
    j = model.joint_positions(f)
    np.testing.assert_allclose(j[names.index("pelvis")], [1.0, 2.0, 0.9])
    np.testing.assert_allclose(j[wr], [1.0 + 0.697, 2.0 - 0.004259, 0.9 + 0.43478], atol=1e-9)


def test_fk_batched_equals_looped(model: HumanModel) -> None:
    f = random_postures(20).reshape(4, 5, 12)
    batched = model.joint_positions(f)
    ends, radii = model.capsules(f)
    pts = model.surface_points(f, spacing=0.05)
    assert batched.shape == (4, 5, len(model.JOINT_NAMES), 3)
    assert ends.shape == (4, 5, len(radii), 2, 3)
    for a in range(4):
        for b in range(5):
            np.testing.assert_allclose(batched[a, b], model.joint_positions(f[a, b]), atol=1e-12)
            np.testing.assert_allclose(ends[a, b], model.capsules(f[a, b])[0], atol=1e-12)
            np.testing.assert_allclose(pts[a, b], model.surface_points(f[a, b], spacing=0.05), atol=1e-12)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


@pytest.mark.parametrize("spacing", [0.02, 0.05])
def test_surface_points_on_capsules_and_dense(model: HumanModel, spacing: float) -> None:
    f = random_postures(3, seed=1)
    pts = model.surface_points(f, spacing=spacing)
    ends, radii = model.capsules(f)
    sizes = [len(s) for s, _ in model._template(spacing, False)]
    rng = np.random.default_rng(2)
    for i in range(len(f)):
        start = 0
        for k, n in enumerate(sizes):
            seg = pts[i, start:start + n]
            a, b = ends[i, k]
            # every sample lies on its capsule's surface (the stretched upper arm to within 0.01 mm: the
            # arm translation runs along -y, 1 degree off the zero-pose shoulder-elbow line)
            np.testing.assert_allclose(_segment_distance(seg, a, b), radii[k], atol=1e-5)
            # and the surface is covered: random surface points have a sample within `spacing`
            axis = (b - a) / np.linalg.norm(b - a)
            u = np.cross(axis, [0.3, 0.5, 0.8])
            u /= np.linalg.norm(u)
            w = np.cross(axis, u)
            t = rng.uniform(0, 1, 200)
            ang = rng.uniform(0, 2 * np.pi, 200)
            probe = a + t[:, None] * (b - a) + radii[k] * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w)
            d = np.linalg.norm(probe[:, None, :] - seg[None, :, :], axis=-1).min(axis=1)
            assert d.max() <= spacing, (model.SEGMENT_NAMES[k], d.max())
            start += n
        assert start == pts.shape[1]


def test_interior_points_fill_the_body(model: HumanModel) -> None:
    f = random_postures(1)[0]
    solid = model.surface_points(f, spacing=0.05, interior=True)
    ends, radii = model.capsules(f)
    torso = model.SEGMENT_NAMES.index("torso")
    d = _segment_distance(solid, *ends[torso])
    assert np.any(d < 0.01)  # points on the torso's axis
    assert len(solid) > model.n_surface_points(0.05)


def test_voxelize() -> None:
    grid = Grid(np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.5, 0.5]), 0.1)
    pts = np.array([[0.05, 0.05, 0.05], [0.95, 0.45, 0.45], [0.51, 0.25, 0.35], [2.0, 0.0, 0.0], [np.nan, 0, 0]])
    occ = voxelize(pts, grid)
    assert occ.shape == (10, 5, 5) and occ.dtype == bool
    assert occ.sum() == 3 and occ[0, 0, 0] and occ[9, 4, 4] and occ[5, 2, 3]
    assert not voxelize(np.zeros((0, 3)), grid).any()
    with pytest.raises(HumanError, match="shape"):
        voxelize(np.zeros((4, 2)), grid)


def test_voxelized_body_matches_capsules(model: HumanModel) -> None:
    scene = load_scene(None)
    f = place_in_scene(random_postures(1)[0], random_postures(1)[0], scene)
    occ = voxelize(model.surface_points(f, spacing=0.02), scene.grid)
    centers = scene.grid.centers()[occ]
    ends, radii = model.capsules(f)
    # every occupied voxel's centre is within half a voxel diagonal of some capsule surface
    dmin = np.min([np.abs(_segment_distance(centers, *ends[k]) - radii[k]) for k in range(len(radii))], axis=0)
    assert dmin.max() <= scene.grid.resolution * math.sqrt(3) / 2 + 1e-9
    assert 50 < occ.sum() < 2000


def test_bad_features_rejected(model: HumanModel) -> None:
    with pytest.raises(HumanError, match=r"\(\.\.\., 12\)"):
        model.joint_positions(np.zeros(11))
    bad = np.zeros(12)
    bad[3] = np.nan
    with pytest.raises(HumanError, match="NaN"):
        model.surface_points(bad)
    with pytest.raises(HumanError, match="spacing"):
        model.surface_points(np.zeros(12), spacing=0.0)


def test_place_in_scene_first_pose_and_relative_motion(model: HumanModel) -> None:
    scene = load_scene(None)
    f = random_postures(30, seed=3)
    placed = place_in_scene(f, f[0], scene)
    np.testing.assert_allclose(placed[0, :3], scene.human.pelvis_xyz, atol=1e-12)
    assert placed[0, 3] == pytest.approx(scene.human.pelvis_yaw)
    np.testing.assert_array_equal(placed[:, 4:], f[:, 4:])
    # relative motion preserved: distances between body points of any two postures are unchanged
    j, jp = model.joint_positions(f), model.joint_positions(placed)
    a, b = j.reshape(-1, 3), jp.reshape(-1, 3)
    da = np.linalg.norm(a[:, None] - a[None], axis=-1)
    db = np.linalg.norm(b[:, None] - b[None], axis=-1)
    np.testing.assert_allclose(da, db, atol=1e-9)
    # the yaw offset is the same for every posture
    np.testing.assert_allclose(placed[:, 3] - f[:, 3], scene.human.pelvis_yaw - f[0, 3], atol=1e-12)
    # batched over demonstrations equals one at a time
    np.testing.assert_allclose(place_in_scene(f.reshape(3, 10, 12), f[0], scene).reshape(30, 12), placed)


def test_paper_library_reach_points_over_table(paper_library, model: HumanModel) -> None:
    from shared.library import load_library

    lib = load_library(paper_library)
    scene = load_scene(None)
    reach, _ = reach_points(model, [d.features for d in lib.demos], scene)
    labels = np.array([d.label for d in lib.demos])
    table = next(b for b in scene.boxes if b.name == "table_top")
    means = np.array([reach[labels == m].mean(axis=0) for m in range(lib.n_classes)])
    spread = np.array([np.linalg.norm(reach[labels == m] - means[m], axis=1).mean() for m in range(lib.n_classes)])
    for m in range(lib.n_classes):
        assert np.all(means[m, :2] > table.lower[:2]) and np.all(means[m, :2] < table.upper[:2]), (m, means[m])
        # in front of the human: farther along its heading than the pelvis
        heading = np.array([math.cos(scene.human.pelvis_yaw), math.sin(scene.human.pelvis_yaw)])
        assert (means[m, :2] - scene.human.pelvis_xyz[:2]) @ heading > 0.3
    d = np.linalg.norm(means[:, None] - means[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    assert np.all(d.min(axis=1) > spread), (d.min(axis=1), spread)
    # most reach points lie over the table top
    inside = np.all((reach[:, :2] > table.lower[:2]) & (reach[:, :2] < table.upper[:2]), axis=1)
    assert inside.mean() > 0.9


def test_a_stream_is_placed_from_each_demonstration_s_first_pose_seen() -> None:
    """``StreamPlacement``: index 0 (or a new demonstration, or the first pose seen of one joined part-way) is the
    reference; the later poses move with it."""
    scene = load_scene(None)
    first, later = np.zeros(12), np.zeros(12)
    first[:4] = [1.0, 2.0, 1.0, 0.3]
    later[:4] = [1.2, 2.0, 1.0, 0.3]
    placement = StreamPlacement(scene)
    np.testing.assert_allclose(placement.place(4, 0, first)[:3], scene.human.pelvis_xyz)
    np.testing.assert_allclose(placement.place(4, 1, later), place_in_scene(later, first, scene))
    np.testing.assert_allclose(placement.place(5, 7, later)[:3], scene.human.pelvis_xyz)  # joined part-way
    np.testing.assert_allclose(placement.place(5, 0, first)[:3], scene.human.pelvis_xyz)  # a run's ids restart
