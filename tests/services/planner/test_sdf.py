"""Signed distance field of the scene and voxel-grid lookups."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from services.planner.sdf import GridLookupError, SignedDistanceField, grid_lookup, rasterize_obstacles


@pytest.fixture(scope="module")
def sdf(scene):
    return SignedDistanceField(scene, resolution=0.02)


def _box_distance(box, p: np.ndarray) -> np.ndarray:
    d = np.maximum(np.maximum(box.lower - p, p - box.upper), 0)
    out = np.linalg.norm(d, axis=-1)
    inside = np.min(np.minimum(p - box.lower, box.upper - p), axis=-1)
    return np.where(out > 0, out, -inside)


def _cup_distance(cup, p: np.ndarray) -> np.ndarray:
    r = np.hypot(p[..., 0] - cup.position[0], p[..., 1] - cup.position[1]) - cup.radius
    z = np.maximum(cup.position[2] - p[..., 2], p[..., 2] - cup.position[2] - cup.height)
    out = np.hypot(np.maximum(r, 0), np.maximum(z, 0))
    return np.where((r > 0) | (z > 0), out, np.maximum(r, z))


def test_sdf_matches_analytic_distance(scene, sdf) -> None:
    rng = np.random.default_rng(0)
    p = rng.uniform([-0.8, -1.2, 0.45], [0.8, -0.25, 1.1], size=(4000, 3))
    exact = np.min(np.stack([_box_distance(b, p) for b in scene.boxes] + [_cup_distance(c, p) for c in scene.cups]),
                   axis=0)
    got = sdf(torch.tensor(p, dtype=torch.float32)).numpy()
    err = np.abs(got - exact)
    assert err.mean() < 0.006
    assert err.max() < 1.5 * sdf.grid.resolution
    # signs: clearly inside negative, clearly outside positive
    assert np.all(got[exact < -0.015] < 0) and np.all(got[exact > 0.03] > 0)


def test_sdf_inside_table_and_above_it(scene, sdf) -> None:
    top = scene.boxes[0]
    c = torch.tensor(top.center, dtype=torch.float32)
    assert float(sdf(c)) < 0
    above = c + torch.tensor([-0.5, 0.0, top.size[2] / 2 + 0.30])  # away from the cups
    assert float(sdf(above)) == pytest.approx(0.30, abs=0.02)


def test_sdf_outside_the_grid_is_positive_and_grows(scene, sdf) -> None:
    far = torch.tensor([[scene.grid.max[0] + 0.5, 0.0, 1.0], [scene.grid.max[0] + 1.5, 0.0, 1.0]])
    d = sdf(far)
    assert float(d[0]) > 0.5 and float(d[1]) > float(d[0]) + 0.9


def test_rasterize_marks_cups(scene, sdf) -> None:
    occ = rasterize_obstacles(scene, sdf.grid)
    for cup in scene.cups:
        idx, inside = sdf.grid.index(cup.center[None])
        assert inside[0] and occ[tuple(idx[0])]


def test_grid_lookup_equals_grid_sample_and_batched_equals_looped() -> None:
    g = torch.Generator().manual_seed(0)
    vol = torch.rand(9, 12, 7, generator=g)
    origin, res = np.array([0.1, -0.2, 0.3]), 0.05
    p = torch.rand(300, 3, generator=g) * torch.tensor([0.6, 0.8, 0.5]) + torch.tensor([0.0, -0.3, 0.2])
    first = torch.tensor(origin, dtype=torch.float32) + res / 2
    n = torch.tensor(vol.shape, dtype=torch.float32)
    grid = ((p - first) / (res * (n - 1)) * 2 - 1).reshape(1, -1, 1, 1, 3)
    v5 = vol.permute(2, 1, 0)[None, None]
    for padding in ("zeros", "border"):
        ref = F.grid_sample(v5, grid, align_corners=True, padding_mode=padding).reshape(-1)
        got = grid_lookup(vol, origin, res, p, padding=padding)
        assert torch.allclose(got, ref, atol=1e-5), padding
    batched = grid_lookup(vol, origin, res, p.reshape(3, 100, 3))
    looped = torch.stack([grid_lookup(vol, origin, res, pi) for pi in p.reshape(3, 100, 3)])
    assert torch.allclose(batched, looped)


def test_grid_lookup_nearest_reads_the_containing_voxel() -> None:
    vol = torch.arange(4 * 5 * 6, dtype=torch.float32).reshape(4, 5, 6)
    origin, res = np.zeros(3), 0.1
    p = torch.tensor([[0.05, 0.05, 0.05], [0.36, 0.12, 0.58], [0.21, 0.49, 0.31]])
    got = grid_lookup(vol, origin, res, p, mode="nearest")
    idx = np.floor(p.numpy() / res).astype(int)
    assert got.tolist() == [float(vol[tuple(i)]) for i in idx]
    # on the faces between voxels (exact in binary): the voxel above each face, as Grid.index; round-half-even gave
    # voxels 1, 1, 3 for the faces of 1, 2, 3
    faces = torch.tensor([[0.25 * i, 0.1, 0.1] for i in (1, 2, 3)])
    got = grid_lookup(vol, origin, 0.25, faces, mode="nearest")
    assert got.tolist() == [float(vol[i, 0, 0]) for i in (1, 2, 3)]


@pytest.mark.parametrize("vol,origin,res,match", [
    (torch.zeros(4, 4), np.zeros(3), 0.1, "nx, ny, nz"),
    (torch.zeros(4, 4, 4), np.zeros(2), 0.1, "origin"),
    (torch.zeros(4, 4, 4), np.zeros(3), -1.0, "resolution"),
])
def test_grid_lookup_bad_input(vol, origin, res, match) -> None:
    with pytest.raises(GridLookupError, match=match):
        grid_lookup(vol, origin, res, torch.zeros(1, 3))
