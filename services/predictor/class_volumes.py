"""The class volumes ``foresight train`` writes into a model: ``p(x|C_m)`` of every class in the scene's grid.

By ``--volume`` (:mod:`services.predictor.volumes`): the body swept along the class's GMR motion (``paper``), the
motion with its spread (``spread``), the training demonstrations swept (``demos``) or those by time (``timed``).
Each class volume and each demonstration's sweep is cached in the trainer's fit cache by a digest of what it
depends on (:mod:`services.predictor.fit_cache`), so models trained on overlapping data share them.
"""

from __future__ import annotations

from collections.abc import MutableMapping
from typing import TYPE_CHECKING, Any

import numpy as np

from shared.feature_sets import FeatureMapping
from shared.human import HumanModel
from shared.library import Demonstration
from shared.progress import progress as progress_bar
from shared.runtime import UserError
from shared.scene import Scene

from .features import FeatureEncoder
from .fit_cache import cached
from .gmm import MixtureBank
from .gmr import gmr
from .model import TimedVolumes
from .swept_volume import swept_volume
from .volumes import Sweep, demos_volume, digest, spread_volume, sweep, timed_volume

if TYPE_CHECKING:
    from .train import TrainConfig

__all__ = ["demo_sweep_key", "class_volumes", "timed_class_volumes"]


def _volume_key_parts(scene: Scene, grid, cfg: TrainConfig) -> tuple:
    pelvis = np.array([*scene.human.pelvis_xyz, scene.human.pelvis_yaw])
    return grid.min, grid.max, grid.resolution, pelvis, cfg.spacing, cfg.interior, cfg.oversample


def demo_sweep_key(features: np.ndarray, scene: Scene, grid, cfg: TrainConfig) -> str:
    """The ``fit_cache`` key of a demonstration's :class:`~services.predictor.volumes.Sweep` (``demos`` volumes).

    Args:
        features: ``(T, F)`` the demonstration's features.
        scene: The scene it is placed in.
        grid: The voxel grid.
        cfg: Training options (spacing, interior, oversample).
    """
    return "sweep:" + digest(np.asarray(features, dtype=np.float64), *_volume_key_parts(scene, grid, cfg))


def _sweeps(demos: list[Demonstration], mapping: FeatureMapping, scene: Scene, grid, cfg: TrainConfig,
            cache: MutableMapping[str, Any], human: HumanModel) -> list[Sweep]:
    """The (cached) sweep of every demonstration of ``demos``."""
    out = []
    for d in demos:
        key = demo_sweep_key(d.features, scene, grid, cfg)
        out.append(cached(cache, key, lambda d=d: sweep(mapping.to_human(d.features), scene, grid, human, cfg.spacing,
                                                        cfg.interior, cfg.oversample)))
    return out


def timed_class_volumes(mapping: FeatureMapping, scene: Scene, grid, cfg: TrainConfig,
                        by_class: list[list[Demonstration]], cache: MutableMapping[str, Any],
                        progress: bool) -> TimedVolumes:
    """The ``timed`` volumes of every class on the union of their supports."""
    if cfg.time_bin < 1:
        raise UserError(f"time bin must be >= 1 sample, got {cfg.time_bin}")
    human = HumanModel()
    n_bins = -(-max(d.n_samples for ds in by_class for d in ds) // cfg.time_bin)
    parts = [timed_volume(_sweeps(ds, mapping, scene, grid, cfg, cache, human), grid, cfg.time_bin, n_bins)
             for ds in progress_bar(by_class, desc="timed volumes", unit="class", enabled=progress)]
    support = np.unique(np.concatenate([p[0] for p in parts]))
    values = np.zeros((len(parts), n_bins, len(support)), np.float32)
    for m, (sup, val) in enumerate(parts):
        values[m][:, np.searchsorted(support, sup)] = val
    return TimedVolumes(support, values, cfg.time_bin)


def class_volumes(bank: MixtureBank, lengths: list[int], encoder: FeatureEncoder, mapping: FeatureMapping,
                   scene: Scene, grid, cfg: TrainConfig, by_class: list[list[Demonstration]],
                   cache: MutableMapping[str, Any], progress: bool) -> np.ndarray:
    """``(M, nx, ny, nz)`` float32 ``p(x|C_m)`` of each class by ``cfg.volume`` (human model via ``mapping``).

    Volumes are cached in ``cache`` by a digest of what they depend on (the class mixture or the
    demonstration, the grid, the placement and the sampling options).
    """
    human = HumanModel()
    common = _volume_key_parts(scene, grid, cfg)
    cols = encoder.posture_columns()
    out = []
    for m in progress_bar(range(len(lengths)), desc=f"{cfg.volume} volumes", unit="class", enabled=progress):
        w, mu, cov = bank.weights_[m], bank.means_[m], bank.covariances_[m]
        if cfg.volume == "demos":
            out.append(demos_volume(_sweeps(by_class[m], mapping, scene, grid, cfg, cache, human), grid))
            continue
        key = f"volume:{cfg.volume}:" + digest(w, mu, cov, lengths[m], encoder.time_scale, *common)

        def make(w: np.ndarray = w, mu: np.ndarray = mu, cov: np.ndarray = cov, n: int = lengths[m]) -> np.ndarray:
            t = np.arange((n - 1) * cfg.oversample + 1) / cfg.oversample * encoder.time_scale
            if cfg.volume == "paper":
                y = np.asarray(gmr(w, mu, cov, t))[:, cols.start - 1: cols.stop - 1]
                return swept_volume(mapping.to_human(y), scene, grid, human, cfg.spacing,
                                    cfg.interior).astype(np.float32)
            y, c = gmr(w, mu, cov, t, return_covariance=True)
            o = slice(cols.start - 1, cols.stop - 1)
            return spread_volume(y[:, o], c[:, o, o], scene, grid, human, cfg.spacing, cfg.interior,
                                 to_human=mapping.to_human)

        out.append(cached(cache, key, make))
    return np.stack(out)
