"""The voxels of body points: batched over postures, as posture by posture."""

from __future__ import annotations

import numpy as np

from services.predictor.swept_volume import posture_voxels, voxels_per_posture
from services.predictor.volumes import interpolate, sweep
from shared.human import HumanModel, place_in_scene


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
