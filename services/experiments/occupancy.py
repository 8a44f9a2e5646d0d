"""``foresight eval occupancy``: does the predicted occupancy hold where the human really goes?

Leave-one-out over the library: for each held-out demonstration the prediction model is trained
without it (only its class is refitted: the per-class fit cache of ``train_model``), the predictor
core observes the demonstration's first 20, 40, 60 and 80% and its published grid is compared with
the truth: the voxels the held-out human's body (the human model's capsules, surface and inside,
placed in the scene relative to the demonstration's first pelvis pose, as the predictor places it)
occupies from that moment to the end of the demonstration. Per fraction, averaged over the held-out
demonstrations:

* recall: the share of the truly occupied voxels whose predicted occupancy is >= 0.1;
* volume ratio: voxels predicted >= 0.1 over truly occupied voxels (1: as large as the truth);
* average precision of the voxel scores against the truth (threshold-free;
  ``sklearn.metrics.average_precision_score`` over every voxel of the grid).

One model per held-out demonstration and volume method (``--methods``); the posterior temperature is
the library's (cross-validated once on the whole library: one number, chosen with the held-out
demonstration among the ~200, is the only thing the model knows of it).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from joblib import Parallel, delayed
from sklearn.metrics import average_precision_score
from threadpoolctl import threadpool_limits

from services.predictor.class_volumes import demo_sweep_key
from services.predictor.core import PredictorCore
from services.predictor.gmm import GMMConfig
from services.predictor.train import TrainConfig, train_model
from services.predictor.volumes import VOLUMES, Sweep, sweep
from shared.human import HumanModel
from shared.library import Demonstration, MotionLibrary
from shared.runtime import UserError
from shared.scene import Grid, Scene

from .heldout import short_name

__all__ = ["FRACTIONS", "THRESHOLD", "OccupancyConfig", "OccupancyResult", "truth_sweep", "truth_after",
           "occupancy_scores", "run_occupancy", "plot_occupancy"]

FRACTIONS = (0.2, 0.4, 0.6, 0.8)
THRESHOLD = 0.1
"""A voxel counts as predicted occupied when its occupancy is at least this."""


@dataclass(frozen=True)
class OccupancyConfig:
    """Options of ``foresight eval occupancy``.

    Attributes:
        methods: Volume methods compared (:data:`services.predictor.volumes.VOLUMES`).
        per_class: Held-out demonstrations per class (0: every one; else evenly spread over the class).
        components: Gaussians per class.
        resolution: Voxel edge (m); None: the scene's grid.
        n_jobs: Parallel worker processes.
        example: Index (in the held-out order) of the demonstration drawn in the PNG.
    """

    methods: tuple[str, ...] = VOLUMES
    per_class: int = 0
    components: int = 20
    resolution: float | None = None
    n_jobs: int = 2
    example: int = 0


@dataclass
class OccupancyResult:
    """Per method, per fraction, the means over the held-out demonstrations.

    Attributes:
        fractions: Executed fractions.
        metrics: ``{method: {"recall" | "volume_ratio" | "average_precision": [per fraction]}}``.
        per_demo: ``{method: (N, F, 3)}`` recall, volume ratio and average precision of every held-out demo.
        held_out: ``(label, index)`` of each held-out demonstration.
        temperature: The posterior temperature used.
        example: Top views of the PNG's example: ``{"truth": (F, nx, ny), method: (F, nx, ny)}``.
        info: Library, scene, grid, timing.
    """

    fractions: list[float]
    metrics: dict[str, dict[str, list[float]]]
    per_demo: dict[str, np.ndarray]
    held_out: list[tuple[int, int]]
    temperature: float
    example: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """``fractions`` and, per method, lists ``recall``, ``volume_ratio``, ``average_precision``."""
        return {"fractions": self.fractions, **self.metrics, "methods": list(self.metrics),
                "threshold": THRESHOLD, "held_out": len(self.held_out), "temperature": self.temperature,
                **self.info}

    def lines(self) -> list[str]:
        """A table: one row per method and fraction."""
        i = self.info
        out = [f"occupancy prediction, leave-one-out: {i['library']} in scene {i['scene']}, grid {i['grid']}, "
               f"{len(self.held_out)} held-out demonstrations, tau {self.temperature:g}, threshold {THRESHOLD}",
               f"{'volume':>8} {'executed':>8} {'recall':>7} {'vol.ratio':>9} {'AP':>6}"]
        for name, m in self.metrics.items():
            for k, f in enumerate(self.fractions):
                out.append(f"{name:>8} {f * 100:7.0f}% {m['recall'][k] * 100:6.1f}% {m['volume_ratio'][k]:9.2f} "
                           f"{m['average_precision'][k]:6.3f}")
        out.append(f"time: {i['seconds']:.0f} s")
        return out


def truth_sweep(features: np.ndarray, scene: Scene, grid: Grid, human: HumanModel | None = None) -> Sweep:
    """The voxels a demonstration's body occupies (surface and inside) and the last sample each is occupied.

    Args:
        features: ``(T, 12)`` recorder-frame postures, placed relative to the first one.
        scene: The scene.
        grid: The voxel grid.
        human: Human model.
    """
    return sweep(features, scene, grid, human, spacing=0.02, interior=True, oversample=4)


def truth_after(truth: Sweep, n_executed: int, grid: Grid) -> np.ndarray:
    """``(V,)`` bool: the voxels occupied from sample ``n_executed - 1`` (the current posture) to the end."""
    return truth.dense(grid, float(n_executed - 1)).ravel()


def occupancy_scores(predicted: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """Recall, volume ratio and average precision of a predicted grid against the truth.

    Args:
        predicted: ``(V,)`` occupancy in [0, 1].
        truth: ``(V,)`` bool, truly occupied voxels (at least one).

    Returns:
        ``(recall, volume_ratio, average_precision)``.
    """
    n_true = int(truth.sum())
    if n_true == 0:
        raise ValueError("the truth has no occupied voxel")
    hit = predicted >= THRESHOLD
    return (float((hit & truth).sum() / n_true), float(hit.sum() / n_true),
            float(average_precision_score(truth, predicted)))


def _executed(n: int) -> np.ndarray:
    return np.clip(np.rint(np.asarray(FRACTIONS) * n).astype(int), 1, n)


def _evaluate(library: MotionLibrary, scene: Scene, cfg: TrainConfig, methods: tuple[str, ...],
              held: list[Demonstration], cache: dict[str, Any], example: tuple[int, int] | None,
              verbose: bool = True) -> list[tuple[np.ndarray, dict[str, np.ndarray] | None]]:
    """Score held-out demonstrations (one worker's share); ``(M methods, F, 3)`` per demo and the example's views.

    With ``verbose``, one progress line per demonstration on stderr (a worker process's output reaches the
    terminal; a callable would have to be pickled to the worker).
    """
    human = HumanModel()
    out = []
    t0 = time.perf_counter()
    with threadpool_limits(1):
        for n, demo in enumerate(held, 1):
            demos = [d for d in library.demos if (d.label, d.index) != (demo.label, demo.index)]
            cores = [PredictorCore(train_model(library, scene, replace(cfg, volume=v), demos, progress=False,
                                               fit_cache=cache), scene) for v in methods]
            grid = cores[0].model.grid
            truth = truth_sweep(demo.features, scene, grid, human)
            ends = _executed(demo.n_samples)
            scores = np.zeros((len(methods), len(FRACTIONS), 3))
            views: dict[str, np.ndarray] | None = {} if example == (demo.label, demo.index) else None
            core = cores[0]
            core.reset(0)
            k = 0
            for i, f in enumerate(demo.features):
                res = core.update(f, i)
                while k < len(ends) and ends[k] == i + 1:
                    t = truth_after(truth, i + 1, grid)
                    for j, c in enumerate(cores):
                        idx, val = c.occupancy_for(res.posterior, i)
                        dense = np.zeros(t.size, np.float32)
                        dense[idx] = val
                        dense = np.rint(dense * 255) / 255  # what the wire carries
                        scores[j, k] = occupancy_scores(dense, t)
                        if views is not None:
                            views.setdefault(methods[j], np.zeros((len(FRACTIONS), *grid.dims[:2])))[k] = \
                                dense.reshape(grid.dims).max(axis=2)
                    if views is not None:
                        views.setdefault("truth", np.zeros((len(FRACTIONS), *grid.dims[:2])))[k] = \
                            t.reshape(grid.dims).any(axis=2)
                    k += 1
            out.append((scores, views))
            if verbose:
                print(f"  held out {demo.class_name} #{demo.index}: {n}/{len(held)} of this worker's share "
                      f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    return out


def _held_out(library: MotionLibrary, per_class: int) -> list[Demonstration]:
    held = []
    for m in range(library.n_classes):
        ds = library.by_class(m)
        if per_class and per_class < len(ds):
            ds = [ds[int(i)] for i in np.unique(np.linspace(0, len(ds) - 1, per_class).round().astype(int))]
        held.extend(ds)
    return held


def _sweep_demo(features: np.ndarray, scene: Scene, grid: Grid, cfg: TrainConfig, to_human) -> Sweep:
    with threadpool_limits(1):
        return sweep(to_human(features), scene, grid, None, cfg.spacing, cfg.interior, cfg.oversample)


def run_occupancy(library: MotionLibrary, scene: Scene, config: OccupancyConfig | None = None,
                  progress: Callable[[str], object] | None = print) -> OccupancyResult:
    """Run the leave-one-out occupancy evaluation.

    Args:
        library: Motion library (>= 2 demonstrations per class, features with a human-model mapping).
        scene: The scene the volumes are placed in.
        config: Options.
        progress: Called with one line per stage (None: silent, also the workers' per-demonstration lines).

    Returns:
        The measures per method and executed fraction.
    """
    verbose = progress is not None
    progress = progress or (lambda _line: None)
    c = config or OccupancyConfig()
    bad = [v for v in c.methods if v not in VOLUMES]
    if bad or not c.methods:
        raise UserError(f"--methods: {', '.join(bad) or 'none given'}; choose among {', '.join(VOLUMES)}")
    if library.mapping is None:
        raise UserError(f"library {library.source}: its features have no mapping to the human model")
    if min(library.counts()) < 2:
        raise UserError(f"library {library.source}: leave-one-out needs >= 2 demonstrations per class")
    held = _held_out(library, c.per_class)
    if not 0 <= c.example < len(held):  # --example 999 drew the last one without a word
        raise UserError(f"--example {c.example}: the held-out demonstrations are 0..{len(held) - 1}")
    t0 = time.perf_counter()
    gmm = GMMConfig(n_components=c.components)
    cfg = TrainConfig(gmm=gmm, resolution=c.resolution)
    grid = scene.grid if c.resolution is None else scene.grid.with_resolution(c.resolution)
    cache: dict[str, Any] = {}
    if "demos" in c.methods:
        progress(f"sweeping the {len(library.demos)} demonstrations ...")
        sweeps = Parallel(n_jobs=c.n_jobs)(delayed(_sweep_demo)(d.features, scene, grid, cfg, library.mapping.to_human)
                                           for d in library.demos)
        cache.update({demo_sweep_key(d.features, scene, grid, cfg): s for d, s in zip(library.demos, sweeps,
                                                                                      strict=True)})
    progress(f"full-library models, tau by {cfg.folds}-fold cross-validation ...")
    with threadpool_limits(1):
        for v in c.methods:
            model = train_model(library, scene, replace(cfg, volume=v), progress=False, fit_cache=cache)
            cfg = replace(cfg, temperature=model.temperature)
    tau = float(cfg.temperature or 0)
    ex = held[c.example]
    progress(f"{len(held)} held-out demonstrations x {len(c.methods)} volume methods on {c.n_jobs} workers ...")
    chunks = [held[i::c.n_jobs] for i in range(c.n_jobs)]
    parts = Parallel(n_jobs=c.n_jobs)(delayed(_evaluate)(library, scene, cfg, c.methods, ch, cache,
                                                         (ex.label, ex.index), verbose) for ch in chunks if ch)
    order = [d for ch in chunks if ch for d in ch]
    results = {(d.label, d.index): r for d, r in zip(order, [r for p in parts for r in p], strict=True)}
    scores = np.stack([results[(d.label, d.index)][0] for d in held])              # (N, methods, F, 3)
    example = next(v for _, v in results.values() if v is not None)
    names = ("recall", "volume_ratio", "average_precision")
    metrics = {v: {n: scores[:, j, :, q].mean(axis=0).tolist() for q, n in enumerate(names)}
               for j, v in enumerate(c.methods)}
    info = {"library": short_name(library.source), "scene": scene.name, "grid": list(grid.dims),
            "resolution": grid.resolution, "example": f"{ex.class_name} #{ex.index}",
            "seconds": time.perf_counter() - t0}
    return OccupancyResult(list(FRACTIONS), metrics, {v: scores[:, j] for j, v in enumerate(c.methods)},
                           [(d.label, d.index) for d in held], tau, example, info)


def plot_occupancy(result: OccupancyResult, path: str | Path, fraction: float = 0.6) -> Path:
    """Recall against volume ratio per method, and the example's top views (truth over prediction).

    Args:
        result: The evaluation.
        path: PNG file.
        fraction: Executed fraction of the example views.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    methods = list(result.metrics)
    k = int(np.argmin(np.abs(np.asarray(result.fractions) - fraction)))
    fig, axes = plt.subplots(1, 1 + len(methods), figsize=(4.6 * (1 + len(methods)), 4.4), dpi=110)
    ax = axes[0]
    for name in methods:
        m = result.metrics[name]
        ax.plot(m["volume_ratio"], np.array(m["recall"]) * 100, marker="o", label=name)
        for f, x, y in zip(result.fractions, m["volume_ratio"], m["recall"], strict=True):
            ax.annotate(f"{f * 100:.0f}%", (x, y * 100), fontsize=7, xytext=(3, -8), textcoords="offset points")
    ax.set_xlabel("volume ratio (voxels >= 0.1 / truly occupied)")
    ax.set_ylabel("recall (% of truly occupied voxels >= 0.1)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{result.info['library']}: leave-one-out, {len(result.held_out)} demos", fontsize=9)
    res = result.info["resolution"]
    truth = result.example["truth"][k]
    for ax, name in zip(axes[1:], methods, strict=True):
        pred = result.example[name][k]
        ax.imshow(pred.T, origin="lower", cmap="Blues", vmin=0, vmax=1, extent=(0, pred.shape[0] * res, 0,
                                                                               pred.shape[1] * res))
        ax.contour(np.arange(truth.shape[0]) * res + res / 2, np.arange(truth.shape[1]) * res + res / 2,
                   truth.T.astype(float), levels=[0.5], colors="red", linewidths=1.2)
        ax.set_title(f"{name}: {result.info['example']} at {result.fractions[k] * 100:.0f}% executed\n"
                     "blue: prediction (max over height), red: truth", fontsize=8)
        ax.set_xlabel("x (m, from the grid's corner)")
        ax.set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(p)
    plt.close(fig)
    return p
