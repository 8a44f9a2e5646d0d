"""Signed distance field of a scene's static obstacles and trilinear lookups in voxel grids.

The scene's boxes and cups are rasterised at the voxel centres of a grid with the scene grid's
bounds (at ``resolution``, finer than the occupancy grid by default), then
``scipy.ndimage.distance_transform_edt`` gives, per voxel, the distance to the nearest voxel of the
other kind; the signed field is ``outside - inside`` with a half-voxel correction so that the zero
level lies on the obstacle surface. Lookups are trilinear (``torch.nn.functional.grid_sample``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from scipy.ndimage import distance_transform_edt

from shared.scene import Grid, Scene

__all__ = ["SignedDistanceField", "rasterize_obstacles", "grid_lookup", "GridLookupError"]


class GridLookupError(ValueError):
    """A voxel volume, origin or resolution is malformed; the message names it."""


def rasterize_obstacles(scene: Scene, grid: Grid, inflate: float = 0.0) -> np.ndarray:
    """Voxels whose centre lies inside a box or a cup of ``scene``.

    Args:
        scene: The scene (``boxes``, ``cups``).
        grid: Voxel grid to rasterise on.
        inflate: Grow every obstacle by this much (m) before rasterising.

    Returns:
        ``(nx, ny, nz)`` bool occupancy.
    """
    c = grid.centers()  # (nx, ny, nz, 3)
    occ = np.zeros(grid.dims, dtype=bool)
    for b in scene.boxes:
        occ |= np.all((c >= b.lower - inflate) & (c <= b.upper + inflate), axis=-1)
    for cup in scene.cups:
        r = np.hypot(c[..., 0] - cup.position[0], c[..., 1] - cup.position[1])
        z = c[..., 2]
        occ |= (r <= cup.radius + inflate) & (z >= cup.position[2] - inflate) & (z <= cup.position[2] + cup.height
                                                                                  + inflate)
    return occ


def _check_volume(volume: torch.Tensor, origin: Any, resolution: float, name: str) -> tuple[torch.Tensor, float]:
    if volume.ndim != 3 or min(volume.shape) < 2:
        raise GridLookupError(f"{name}: expected a (nx, ny, nz) volume with every size >= 2, "
                              f"got shape {tuple(volume.shape)}")
    o = torch.as_tensor(np.asarray(origin, dtype=np.float64)).reshape(-1)
    if o.shape != (3,) or not torch.isfinite(o).all():
        raise GridLookupError(f"{name}: origin must be 3 finite numbers, got {origin!r}")
    if not (isinstance(resolution, int | float) and np.isfinite(resolution) and resolution > 0):
        raise GridLookupError(f"{name}: resolution must be a positive number, got {resolution!r}")
    return o, float(resolution)


class _Lookup:
    """Trilinear (or nearest) lookup in one voxel volume whose values sit at the voxel centres.

    The 8 corner values of every cell are packed next to each other once, so that a lookup is one
    ``index_select`` of ``(N, 8)`` rows and 7 lerps (no ``.item()``, no host sync).
    ``padding="zeros"`` pads the volume with one voxel of zeros on every side (0 beyond the volume,
    fading linearly over the outer half-voxel); ``"border"`` clamps the query to the outer voxel centres.
    """

    def __init__(self, volume: torch.Tensor, origin: Any, resolution: float, padding: str, name: str) -> None:
        o, res = _check_volume(volume, origin, resolution, name)
        if padding not in ("zeros", "border"):
            raise GridLookupError(f"{name}: padding must be 'zeros' or 'border', got {padding!r}")
        dev, dt = volume.device, volume.dtype
        first = o + res / 2  # centre of voxel 0
        if padding == "zeros":
            volume = F.pad(volume, (1, 1, 1, 1, 1, 1))
            first = first - res
        self.dims = tuple(int(n) for n in volume.shape)
        nx, ny, nz = self.dims
        corners = [volume[dx:nx - 1 + dx, dy:ny - 1 + dy, dz:nz - 1 + dz]
                   for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)]
        self.packed = torch.stack(corners, -1).reshape(-1, 8).contiguous()
        self.flat = volume.reshape(-1).contiguous()
        self.first = first.to(dev, dt)
        self.inv_res = 1.0 / res
        self.cell_max = torch.tensor([nx - 2, ny - 2, nz - 2], device=dev)
        self.u_max = torch.tensor([nx - 1, ny - 1, nz - 1], device=dev, dtype=dt)
        self.cell_strides = torch.tensor([(ny - 1) * (nz - 1), nz - 1, 1], device=dev)
        self.voxel_strides = torch.tensor([ny * nz, nz, 1], device=dev)

    def __call__(self, points: torch.Tensor, mode: str = "trilinear") -> torch.Tensor:
        lead = points.shape[:-1]
        u = ((points.reshape(-1, 3) - self.first) * self.inv_res).clamp(min=0)
        u = torch.minimum(u, self.u_max)
        if mode == "nearest":
            idx = (torch.round(u).long() * self.voxel_strides).sum(-1)
            return self.flat.index_select(0, idx).reshape(lead)
        i0 = torch.minimum(u.long(), self.cell_max)
        f = u - i0
        c = self.packed.index_select(0, (i0 * self.cell_strides).sum(-1))  # (N, 8) ordered x, y, z bits
        fx, fy, fz = f[:, 0:1], f[:, 1:2], f[:, 2:3]
        c = c.view(-1, 4, 2)
        c = c[..., 0] + (c[..., 1] - c[..., 0]) * fz  # (N, 4)
        c = c.view(-1, 2, 2)
        c = c[..., 0] + (c[..., 1] - c[..., 0]) * fy  # (N, 2)
        return (c[:, 0] + (c[:, 1] - c[:, 0]) * fx[:, 0]).reshape(lead)


def grid_lookup(volume: torch.Tensor, origin: Any, resolution: float, points: torch.Tensor,
                mode: str = "trilinear", padding: str = "zeros") -> torch.Tensor:
    """Interpolate a voxel volume at points (values at voxel centres).

    Args:
        volume: ``(nx, ny, nz)`` values; voxel (i, j, k) is centred at ``origin + res * ((i, j, k) + 0.5)``.
        origin: ``(3,)`` lower corner of voxel (0, 0, 0).
        resolution: Voxel edge (m).
        points: ``(..., 3)`` query positions.
        mode: ``"trilinear"`` or ``"nearest"`` (the value of the voxel whose centre is nearest).
        padding: ``"zeros"`` (0 outside the volume) or ``"border"`` (clamp to the border).

    Returns:
        ``(...)`` interpolated values.
    """
    if mode not in ("trilinear", "nearest"):
        raise GridLookupError(f"mode must be 'trilinear' or 'nearest', got {mode!r}")
    return _Lookup(volume, origin, resolution, padding, "volume")(points, mode)


class SignedDistanceField:
    """Signed Euclidean distance to the scene's static obstacles (boxes and cups).

    Args:
        scene: The scene.
        resolution: Voxel edge of the field (m); None: the scene grid's resolution.
        device, dtype: Where the field lives for lookups.

    Attributes:
        grid: The field's voxel grid (scene grid bounds, ``resolution``).
        occupied_: ``(nx, ny, nz)`` bool rasterised obstacles.
        distance_: ``(nx, ny, nz)`` float32 numpy signed distance (m): negative inside obstacles.
    """

    def __init__(self, scene: Scene, resolution: float | None = 0.02, device: str | torch.device = "cpu",
                 dtype: torch.dtype = torch.float32) -> None:
        self.grid = scene.grid if resolution is None else scene.grid.with_resolution(resolution)
        res = self.grid.resolution
        occ = rasterize_obstacles(scene, self.grid)
        self.occupied_ = occ
        if occ.all():
            raise GridLookupError("signed distance field: every voxel is inside an obstacle")
        outside = distance_transform_edt(~occ) * res if occ.any() else np.full(occ.shape, 1e3)
        inside = distance_transform_edt(occ) * res
        # voxel-centre distances -> distance to the surface halfway between the two voxel kinds
        sdf = np.where(occ, -(inside - res / 2), outside - res / 2)
        self.distance_ = sdf.astype(np.float32)
        self.device, self.dtype = torch.device(device), dtype
        self._lookup = _Lookup(torch.as_tensor(self.distance_, device=self.device, dtype=dtype), self.grid.origin,
                               res, "border", "signed distance field")
        lo = torch.as_tensor(self.grid.min, device=self.device, dtype=dtype)
        hi = torch.as_tensor(self.grid.max, device=self.device, dtype=dtype)
        self._lo, self._hi = lo, hi

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance (m) at ``points`` ``(..., 3)`` -> ``(...)``.

        Outside the grid: the value at the nearest border voxel centre plus the distance to the grid
        box (the scene's obstacles lie inside the grid, so this stays positive and grows outwards).
        """
        d = self._lookup(points)
        out = torch.clamp(self._lo - points, min=0) + torch.clamp(points - self._hi, min=0)
        return d + torch.sqrt((out * out).sum(-1))  # (vector_norm over a size-3 axis is slow on CPU)
