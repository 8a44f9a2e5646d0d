"""Per-class occupancy volumes p(x | C_m): which voxels a class's motion occupies, and how likely.

Four ways to build them (``foresight train --volume``, stored in the model file):

- ``paper``: the body swept along the class's GMR *mean* motion (the paper, IV.D); 0/1.
- ``spread``: the class's motion *with its spread*: ``n_samples`` posture trajectories drawn from
  the GMR conditional distribution ``N(E[y|t], Cov[y|t])`` (one standard-normal draw per trajectory,
  shared by all times and shaped by the Cholesky factor of each time's covariance, so a draw is a
  smooth motion), each swept like the paper's; ``p(x|C_m)`` is the share of the trajectories whose
  body hits the voxel. A class with zero conditional covariance gives the paper's volume back.
- ``demos``: the class's training demonstrations themselves, each placed in the scene relative to
  its own first pelvis pose and swept; ``p(x|C_m)`` is the share of the demonstrations whose body
  hits the voxel (an empirical probability that a new demonstration of the class does).
- ``timed``: ``demos`` indexed by time: ``p(x|C_m, t)`` is the share of the demonstrations whose body
  hits the voxel at sample ``t`` or later, kept in bins of ``time_bin`` samples (the bin's start
  counts, so a bin never drops what is still to come). The predictor publishes, at the observed
  sample index t, only what the human may still occupy: where the arm has already been is free.

All take postures in the human model's 12 joint values (``FeatureMapping.to_human`` applied).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from shared.human import HumanModel, place_in_scene
from shared.scene import Grid, Scene

from .swept_volume import posture_chunk, swept_volume, voxels_per_posture

__all__ = ["VOLUMES", "DEFAULT_VOLUME", "Sweep", "sweep", "interpolate", "spread_volume",
           "demos_volume", "timed_volume", "digest"]

VOLUMES = ("paper", "spread", "demos", "timed")
DEFAULT_VOLUME = "demos"
"""The default of ``foresight train --volume``, chosen in the loop by ``foresight eval volumes``."""
SPREAD_SAMPLES = 16
"""Trajectories drawn per class for the ``spread`` volume."""


def digest(*parts: object) -> str:
    """A short hash of arrays and values (cache keys): each array's dtype, shape and bytes, each value's repr.

    Every part is framed by its kind and length, so two different lists of parts never hash the same bytes
    (e.g. one array of 6 values and two of 3 with the same bytes).
    """
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            head, body = f"array {a.dtype.str} {a.shape}", a.tobytes()
        else:
            head, body = "value", repr(p).encode()
        h.update(f"{head} {len(body)}:".encode())
        h.update(body)
    return h.hexdigest()[:24]


def interpolate(motion: np.ndarray, oversample: int) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation between consecutive postures.

    Args:
        motion: ``(T, F)`` postures.
        oversample: Postures per sample interval (1: the motion itself).

    Returns:
        ``(postures ((T - 1) * oversample + 1, F), times (same,))``: times in samples of ``motion``.
    """
    m = np.asarray(motion, dtype=np.float64)
    t = np.arange((len(m) - 1) * oversample + 1) / oversample
    k = np.minimum(np.floor(t).astype(int), len(m) - 1)
    k1 = np.minimum(k + 1, len(m) - 1)
    a = (t - k)[:, None]
    return m[k] * (1 - a) + m[k1] * a, t


@dataclass(frozen=True)
class Sweep:
    """The voxels a body hits along one motion, and when it last hits each.

    Attributes:
        indices: ``(N,)`` flat C-order voxel indices, sorted.
        last: ``(N,)`` float32 the last time (in samples of the motion) a posture hits the voxel.
    """

    indices: np.ndarray
    last: np.ndarray

    def after(self, t: float) -> np.ndarray:
        """Flat indices of the voxels hit at time ``t`` or later."""
        return self.indices[self.last >= t]

    def dense(self, grid: Grid, t: float = 0.0) -> np.ndarray:
        """``(nx, ny, nz)`` bool: the voxels hit at time ``t`` or later."""
        out = np.zeros(int(np.prod(grid.dims)), dtype=bool)
        out[self.after(t)] = True
        return out.reshape(grid.dims)


def sweep(motion: np.ndarray, scene: Scene, grid: Grid, human: HumanModel | None = None, spacing: float = 0.02,
          interior: bool = False, oversample: int = 4, chunk: int = 64) -> Sweep:
    """Sweep the body along a recorded motion placed in the scene relative to its own first posture.

    Args:
        motion: ``(T, 12)`` human-model postures (recorder frame).
        scene: Scene giving the human's placement.
        grid: Voxel grid.
        human: Human model (default: a new one).
        spacing: Surface sample spacing (m).
        interior: Also sample the inside of the body (what the body occupies, not only its surface).
        oversample: Interpolated postures per sample interval (the body should move less than a voxel
            between postures).
        chunk: Postures per batch at 2 cm spacing (:func:`~.swept_volume.posture_chunk`).

    Returns:
        The voxels hit and the last time each is hit.
    """
    human = human or HumanModel()
    chunk = posture_chunk(chunk, spacing)
    m = np.asarray(motion, dtype=np.float64)
    dense, times = interpolate(m, oversample)
    placed = place_in_scene(dense, m[0], scene)
    n = int(np.prod(grid.dims))
    last = np.full(n, -1.0, dtype=np.float32)
    for s in range(0, len(placed), chunk):
        pts = human.surface_points(placed[s:s + chunk], spacing=spacing, interior=interior)  # (C, P, 3)
        for j, voxels in enumerate(voxels_per_posture(pts, grid)):
            last[voxels] = times[s + j]  # times increase: the last write is the last hit
    idx = np.flatnonzero(last >= 0)
    return Sweep(idx, last[idx])


def _draw(mean: np.ndarray, cov: np.ndarray, n_samples: int, seed: int) -> np.ndarray:
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    f = mean.shape[1]
    scale = np.trace(cov, axis1=1, axis2=2) / f                              # (T,)
    chol = np.zeros_like(cov)
    pos = scale > 0
    if np.any(pos):
        jitter = 1e-9 * scale[pos, None, None] * np.eye(f)
        chol[pos] = np.linalg.cholesky(cov[pos] + jitter)
    z = np.random.default_rng(seed).standard_normal((n_samples, f))
    return mean[None] + np.einsum("tij,sj->sti", chol, z)


def spread_volume(mean: np.ndarray, cov: np.ndarray, scene: Scene, grid: Grid, human: HumanModel | None = None,
                  spacing: float = 0.02, interior: bool = False, n_samples: int = SPREAD_SAMPLES, seed: int = 0,
                  to_human=None) -> np.ndarray:
    """``p(x|C_m)``: the share of trajectories drawn within the motion's spread whose body hits each voxel.

    Args:
        mean: ``(T, F)`` the regressed (mean) motion, densely sampled.
        cov: ``(T, F, F)`` its conditional covariance at each time.
        scene: Scene giving the human's placement.
        grid: Voxel grid.
        human: Human model (default: a new one).
        spacing: Surface sample spacing (m).
        interior: Also sample the inside of the body.
        n_samples: Trajectories drawn.
        seed: Seed of the draws.
        to_human: Feature mapping to the human model's 12 joint values (default: identity).

    Returns:
        ``(nx, ny, nz)`` float32 in [0, 1]; equal to the paper's (0/1) volume of ``mean`` when ``cov`` is 0.
    """
    human = human or HumanModel()
    conv = to_human or (lambda x: x)
    draws = _draw(np.asarray(mean, np.float64), np.asarray(cov, np.float64), n_samples, seed)
    acc = np.zeros(grid.dims, dtype=np.float32)
    for d in draws:
        acc += swept_volume(conv(d), scene, grid, human, spacing, interior)
    return acc / np.float32(n_samples)


def demos_volume(sweeps: list[Sweep], grid: Grid) -> np.ndarray:
    """``p(x|C_m)``: the share of the class's demonstrations whose swept body hits each voxel.

    Args:
        sweeps: One :class:`Sweep` per training demonstration of the class.
        grid: The voxel grid.

    Returns:
        ``(nx, ny, nz)`` float32 in [0, 1].
    """
    acc = np.zeros(int(np.prod(grid.dims)), dtype=np.float32)
    for s in sweeps:
        acc[s.indices] += 1.0
    return (acc / np.float32(max(1, len(sweeps)))).reshape(grid.dims)


def timed_volume(sweeps: list[Sweep], grid: Grid, time_bin: int, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """``p(x|C_m, t)``: the share of the class's demonstrations whose body hits a voxel at ``t`` or later.

    Args:
        sweeps: One :class:`Sweep` per training demonstration of the class.
        grid: The voxel grid.
        time_bin: Samples per time bin.
        n_bins: Number of bins B (bin b starts at sample ``b * time_bin``).

    Returns:
        ``(support (U,) int64, values (B, U) float32)``: the voxels any demonstration hits, and per
        bin the share of the demonstrations that hit each at or after the bin's start (bin 0: the
        ``demos`` volume).
    """
    support = np.unique(np.concatenate([s.indices for s in sweeps])) if sweeps else np.zeros(0, np.int64)
    acc = np.zeros((n_bins, len(support)), dtype=np.float32)
    starts = np.arange(n_bins, dtype=np.float32) * time_bin
    for s in sweeps:
        pos = np.searchsorted(support, s.indices)
        acc[:, pos] += (s.last[None, :] >= starts[:, None])
    return support, acc / np.float32(max(1, len(sweeps)))
