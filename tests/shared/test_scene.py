"""The voxel grid's indexing of points."""

from __future__ import annotations

import numpy as np

from shared.scene import Grid, load_scene


def test_index_puts_a_point_on_a_voxel_face_in_the_voxel_above_it() -> None:
    grid = load_scene("pr2_two_cups_side").grid  # min (-1, -2, 0), 5 cm voxels
    assert np.allclose(grid.min, [-1.0, -2.0, 0.0]) and grid.resolution == 0.05
    x = np.round(grid.min[0] + grid.resolution * np.arange(grid.dims[0] + 1), 10)  # every x face as typed: -0.9
    points = np.stack([x, np.full_like(x, -1.975), np.full_like(x, 0.025)], axis=-1)
    idx, inside = grid.index(points)
    assert idx[:-1, 0].tolist() == list(range(grid.dims[0]))  # -0.9 gave 1 (1.9999999999999996), not 2: 16 of 47
    assert inside.tolist() == [True] * grid.dims[0] + [False]  # the max face is outside: voxels span [i, i+1)


def test_index_of_points_inside_and_outside() -> None:
    grid = Grid(np.zeros(3), np.ones(3), 0.25)
    idx, inside = grid.index(np.array([[0.1, 0.3, 0.99], [-0.01, 0.5, 0.5], [0.5, 0.5, 1.2]]))
    assert idx.tolist() == [[0, 1, 3], [0, 2, 2], [2, 2, 3]]  # clipped to the grid
    assert inside.tolist() == [True, False, False]
