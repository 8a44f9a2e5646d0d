"""Signed distance field of a scene's static obstacles and trilinear lookups in voxel grids.

The scene's boxes and cups are rasterised at the voxel centres of a grid with the scene grid's
bounds (at ``resolution``, finer than the occupancy grid by default), then
``scipy.ndimage.distance_transform_edt`` gives, per voxel, the distance to the nearest voxel of the
other kind; the signed field is ``outside - inside`` with a half-voxel correction so that the zero
level lies on the obstacle surface. Lookups are trilinear, from :class:`VoxelTables` (tested equal to
``torch.nn.functional.grid_sample``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from scipy.ndimage import distance_transform_edt

from shared.scene import Grid, Scene

__all__ = ["SignedDistanceField", "VoxelTables", "rasterize_obstacles", "grid_lookup", "GridLookupError", "crop_volume"]


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


@dataclass(frozen=True)
class VoxelTables:
    """Lookup tables of one voxel volume whose values sit at the voxel centres (built once per volume).

    A trilinear lookup of a point reads the 8 corner values of the cell (the box between 8 neighbouring
    voxel centres) it falls in: ``cells`` holds them packed next to each other, corner-major, so that a
    lookup is one gather and 7 lerps (no ``.item()``, no host sync); ``volume`` is the same data
    unpacked (8x smaller; a compiled kernel gathers the corners from it with ``corner_offsets``). The
    geometry fields are float so that a kernel computes indices without a dtype change; indices are
    exact below 2^24 voxels in float32.

    Attributes:
        volume: ``(nx, ny, nz)`` values (contiguous), every size >= 2.
        cells: ``(8, C)`` corner values of the C = (nx-1)(ny-1)(nz-1) cells; corner ``4 dx + 2 dy + dz``.
        first: ``(3,)`` position of the centre of voxel (0, 0, 0) (m).
        inv_res: 1 / voxel edge (1/m).
        u_max: ``(3,)`` last voxel index per axis (float).
        cell_max: ``(3,)`` last cell index per axis (float).
        cell_strides: ``(3,)`` flat-index strides of ``cells`` (float).
        voxel_strides: ``(3,)`` flat-index strides of ``volume`` (float).
        corner_offsets: ``(8,)`` long flat offsets of a cell's 8 corners in ``volume``.
    """

    volume: torch.Tensor
    cells: torch.Tensor
    first: torch.Tensor
    inv_res: float
    u_max: torch.Tensor
    cell_max: torch.Tensor
    cell_strides: torch.Tensor
    voxel_strides: torch.Tensor
    corner_offsets: torch.Tensor

    @classmethod
    def build(cls, volume: torch.Tensor, first: torch.Tensor, inv_res: float) -> VoxelTables:
        """Tables of ``volume`` ``(nx, ny, nz)`` (sizes >= 2) whose voxel (0, 0, 0) is centred at ``first`` (3,)."""
        dev, dt = volume.device, volume.dtype
        nx, ny, nz = (int(n) for n in volume.shape)
        corners = [volume[dx:nx - 1 + dx, dy:ny - 1 + dy, dz:nz - 1 + dz].reshape(-1)
                   for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)]

        def vec(values: list[int], dtype: torch.dtype = dt) -> torch.Tensor:
            return torch.tensor(values, device=dev, dtype=dtype)

        return cls(volume=volume.contiguous(), cells=torch.stack(corners).contiguous(), first=first.to(dev, dt),
                   inv_res=float(inv_res), u_max=vec([nx - 1, ny - 1, nz - 1]), cell_max=vec([nx - 2, ny - 2, nz - 2]),
                   cell_strides=vec([(ny - 1) * (nz - 1), nz - 1, 1]), voxel_strides=vec([ny * nz, nz, 1]),
                   corner_offsets=vec([dx * ny * nz + dy * nz + dz for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)],
                                      torch.long))

    @classmethod
    def from_grid(cls, volume: torch.Tensor, origin: Any, resolution: float, padding: str,
                  name: str = "volume") -> VoxelTables:
        """Validated tables of a grid's values.

        Args:
            volume: ``(nx, ny, nz)`` values; voxel (i, j, k) is centred at ``origin + res * ((i, j, k) + 0.5)``.
            origin: ``(3,)`` lower corner of voxel (0, 0, 0) (m).
            resolution: Voxel edge (m).
            padding: ``"zeros"``: one voxel of zeros on every side (0 beyond the volume, fading linearly
                over the outer half-voxel); ``"border"``: lookups clamp to the outer voxel centres.
            name: What the volume is, for error messages.

        Raises:
            GridLookupError: Bad shape (every size >= 2), origin, resolution or padding, or more voxels
                than float32 indexes exactly.
        """
        o, res = _check_volume(volume, origin, resolution, name)
        if padding not in ("zeros", "border"):
            raise GridLookupError(f"{name}: padding must be 'zeros' or 'border', got {padding!r}")
        first = o + res / 2  # centre of voxel 0
        if padding == "zeros":
            volume = F.pad(volume, (1, 1, 1, 1, 1, 1))
            first = first - res
        if volume.dtype != torch.float64 and volume.numel() >= 2**24:
            raise GridLookupError(f"{name}: {volume.numel()} voxels are too many for {volume.dtype} lookups "
                                  "(< 2^24; use float64)")
        return cls.build(volume, first, 1.0 / res)

    def lookup(self, points: torch.Tensor, mode: str = "trilinear") -> torch.Tensor:
        """Values at ``points`` ``(..., 3)`` -> ``(...)``.

        ``mode``: ``"trilinear"``, or ``"nearest"`` (the voxel containing the point; on a face, the one above it).
        Beyond the outer voxel centres the query is clamped to them.
        """
        lead = points.shape[:-1]
        u = ((points.reshape(-1, 3) - self.first) * self.inv_res).clamp(min=0)
        u = torch.minimum(u, self.u_max)
        if mode == "nearest":
            # floor(u + 1/2), not round: round-half-even put points on a face in the upper voxel at some faces and
            # the lower at others. u is taken from the first voxel's centre, so a point exactly on a face can still
            # land on the other side of it from Grid.index's [i, i + 1) by rounding (17-25 of 139 face points in
            # a review): a point on a face is at both voxels' edge, and either value is the field there
            idx = (torch.floor(u + 0.5) * self.voxel_strides).sum(-1).long()
            return self.volume.view(-1).index_select(0, idx).reshape(lead)
        i0 = torch.minimum(u.floor(), self.cell_max)
        f = u - i0
        c = self.cells.index_select(1, (i0 * self.cell_strides).sum(-1).long())  # (8, N) ordered x, y, z bits
        fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]
        c = c.view(4, 2, -1)
        c = c[:, 0] + (c[:, 1] - c[:, 0]) * fz  # (4, N)
        c = c.view(2, 2, -1)
        c = c[:, 0] + (c[:, 1] - c[:, 0]) * fy  # (2, N)
        return (c[0] + (c[1] - c[0]) * fx).reshape(lead)


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
    return VoxelTables.from_grid(volume, origin, resolution, padding).lookup(points, mode)


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
        tables: :class:`VoxelTables` of ``distance_`` (border padding) on ``device`` in ``dtype``.
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
        self.tables = VoxelTables.from_grid(torch.as_tensor(self.distance_, device=self.device, dtype=dtype),
                                            self.grid.origin, res, "border", "signed distance field")
        lo = torch.as_tensor(self.grid.min, device=self.device, dtype=dtype)
        hi = torch.as_tensor(self.grid.max, device=self.device, dtype=dtype)
        self._lo, self._hi = lo, hi

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance (m) at ``points`` ``(..., 3)`` -> ``(...)``.

        Outside the grid: the value at the nearest border voxel centre plus the distance to the grid
        box (the scene's obstacles lie inside the grid, so this stays positive and grows outwards).
        """
        d = self.tables.lookup(points)
        out = torch.clamp(self._lo - points, min=0) + torch.clamp(points - self._hi, min=0)
        return d + torch.sqrt((out * out).sum(-1))  # (vector_norm over a size-3 axis is slow on CPU)


def crop_volume(volume: torch.Tensor, first: torch.Tensor, res: float,
                keep: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """Crop ``volume`` ``(nx, ny, nz)`` to the voxels where ``keep`` holds, plus one layer on every side.

    ``first``: ``(3,)`` the centre of its voxel 0; ``res``: its voxel edge (the fused cost keeps the part of the
    static field where some sphere can pay).

    Returns:
        ``(cropped volume, centre of its voxel 0, whether the crop is strictly inside the volume)``.
    """
    dims = volume.shape
    if not bool(keep.any()):
        lo, hi = [0, 0, 0], [min(1, n - 1) for n in dims]
        inside = False
    else:
        idx = torch.nonzero(keep)
        lo = [max(int(v) - 1, 0) for v in idx.min(0).values]
        hi = [min(int(v) + 1, n - 1) for v, n in zip(idx.max(0).values, dims, strict=True)]
        inside = all(a_ > 0 for a_ in lo) and all(b_ < n - 1 for b_, n in zip(hi, dims, strict=True))
    hi = [max(h, a_ + 1) for a_, h in zip(lo, hi, strict=True)]  # at least 2 voxels per axis
    sub = volume[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1].contiguous()
    return sub, first + res * torch.tensor(lo, dtype=first.dtype, device=first.device), inside
