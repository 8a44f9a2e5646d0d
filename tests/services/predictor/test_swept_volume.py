"""The voxels of body points: batched over postures, as posture by posture."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from services.predictor.gmm import GMMConfig
from services.predictor.swept_volume import (
    posture_chunk,
    posture_voxels,
    surface_spacing,
    swept_volume,
    voxels_per_posture,
)
from services.predictor.train import TrainConfig, train_model
from services.predictor.volumes import interpolate, sweep
from shared.human import HumanModel, place_in_scene
from shared.runtime import UserError
from shared.synthetic import generate_library


def test_voxels_per_posture_equals_each_posture_alone(scene) -> None:
    rng = np.random.default_rng(0)
    lo, hi = scene.grid.min, scene.grid.max
    # points inside and outside the grid, and a posture with none inside
    points = rng.uniform(lo - 0.3, hi + 0.3, size=(5, 400, 3))
    points[3] = hi + 1.0
    batched = voxels_per_posture(points, scene.grid)
    assert len(batched) == 5
    for j in range(5):
        assert np.array_equal(np.unique(batched[j]), posture_voxels(points[j], scene.grid)), j
    assert batched[3].size == 0
    cell = np.floor((points - lo) / scene.grid.resolution)
    inside = np.all((cell >= 0) & (cell < np.array(scene.grid.dims)), axis=-1).sum(axis=1)
    assert [len(b) for b in batched] == inside.tolist()  # one index per point inside, repeats kept


def test_a_sweep_marks_each_voxel_with_the_last_posture_that_hits_it(small_library, scene) -> None:
    human = HumanModel()
    motion = small_library.mapping.to_human(small_library.demos[0].features)
    got = sweep(motion, scene, scene.grid, human, oversample=2, chunk=7)  # several chunks, one short
    dense, times = interpolate(np.asarray(motion, dtype=np.float64), 2)
    placed = place_in_scene(dense, motion[0], scene)
    last: dict[int, float] = {}
    for j, posture in enumerate(placed):  # posture by posture, unbatched
        for v in posture_voxels(human.surface_points(posture), scene.grid):
            last[int(v)] = float(times[j])
    assert got.indices.tolist() == sorted(last)
    assert np.allclose(got.last, [last[v] for v in got.indices.tolist()])


def test_the_surface_is_sampled_as_densely_relative_to_the_voxels_at_any_resolution(scene) -> None:
    """A fixed 2 cm spacing left holes in finer grids: 79 % of one posture's surface voxels missed at 1 cm."""
    assert surface_spacing(0.02, 0.05) == 0.02 and surface_spacing(0.02, 0.1) == 0.02  # the default: unchanged
    assert surface_spacing(0.02, 0.01) == pytest.approx(0.004) and surface_spacing(0.001, 0.05) == 0.001
    human = HumanModel()
    f = generate_library(n_classes=1, n_demos=1, seed=0).demos[0].features
    posture = place_in_scene(f[50], f[0], scene)
    missed = {}
    for res in (0.05, 0.01):
        grid = scene.grid.with_resolution(res)
        dense = posture_voxels(human.surface_points(posture, spacing=0.002), grid)
        for spacing in (0.02, surface_spacing(0.02, res)):
            got = posture_voxels(human.surface_points(posture, spacing=spacing), grid)
            missed[res, spacing] = np.setdiff1d(dense, got).size / dense.size
    assert missed[0.01, 0.02] > 0.5  # the old fixed spacing
    assert missed[0.01, surface_spacing(0.02, 0.01)] <= missed[0.05, 0.02] + 0.02  # as at the default resolution


def test_a_finer_spacing_sweeps_fewer_postures_at_a_time_with_the_same_voxels(small_library, scene) -> None:
    assert posture_chunk(64, 0.02) == 64 and posture_chunk(64, 0.004) == 2 and posture_chunk(64, 0.0001) == 1
    grid = scene.grid.with_resolution(0.1)
    motion = small_library.demos[0].features[:12]
    a, b = sweep(motion, scene, grid, spacing=0.01, chunk=64), sweep(motion, scene, grid, spacing=0.01, chunk=1)
    np.testing.assert_array_equal(a.indices, b.indices)
    np.testing.assert_array_equal(a.last, b.last)
    np.testing.assert_array_equal(swept_volume(motion, scene, grid, spacing=0.01, chunk=64),
                                  swept_volume(motion, scene, grid, spacing=0.01, chunk=1))


def test_training_samples_the_surface_for_its_grid_and_refuses_a_bad_spacing(scene) -> None:
    cfg = TrainConfig(gmm=GMMConfig(n_components=2, max_iter=20), resolution=0.04, oversample=1, volume="paper",
                      temperature=1.0)
    two = generate_library(n_classes=2, n_demos=4, seed=1)
    assert train_model(two, scene, cfg, progress=False).spacing == pytest.approx(0.016)
    with pytest.raises(UserError, match="spacing must be a finite number > 0 m, got nan"):
        train_model(two, scene, dataclasses.replace(cfg, spacing=math.nan), progress=False)


def test_a_point_on_a_voxel_face_is_in_the_voxel_above_it() -> None:
    # pr2_two_cups_side's grid: (x - -1) / 0.05 at x = -0.9 rounds to 1.9999999999999996; of the faces written as
    # decimals 16 of 47 in x, 17 of 47 in y and 12 of 39 in z fell into the voxel below them
    from shared.scene import load_scene

    grid = load_scene("pr2_two_cups_side").grid
    for axis in range(3):
        n = grid.dims[axis]
        faces = np.tile(grid.min + grid.resolution * 0.5, (n - 1, 1))
        faces[:, axis] = np.round(grid.min[axis] + grid.resolution * np.arange(1, n), 10)
        idx, inside = grid.index(faces)
        assert inside.all() and idx[:, axis].tolist() == list(range(1, n)), axis
        flat = np.ravel_multi_index(idx.T, grid.dims)
        assert posture_voxels(faces, grid).tolist() == sorted(flat.tolist()), axis
        assert np.concatenate(voxels_per_posture(faces[None], grid)).tolist() == flat.tolist(), axis
