"""Pictures of a prediction model: the classes' swept volumes and one prediction sequence (paper Fig. 3).

``python -m services.predictor.plots --model MODEL [--library PATH] [--out-dir runs/plots]`` writes

- ``swept_volumes.png``: one top-view panel per class: its swept-volume voxels, its regressed hand
  path, the final hand positions of its demonstrations (placed in the scene), the table and the cups;
- ``prediction_sequence.png``: the predicted occupancy p(x|xi) while one demonstration is observed,
  at several executed fractions, from above (voxels coloured by probability, blue low, red high),
  with the human's current posture.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from shared.arguments import ArgumentParser
from shared.feature_sets import require_mapping
from shared.human import HumanModel, place_in_scene, reach_points
from shared.library import MotionLibrary, heldout_split, load_library
from shared.runtime import cli_errors
from shared.scene import Scene, load_scene

from .core import PredictorCore
from .model import PredictionModel
from .train import default_library

__all__ = ["plot_swept_volumes", "plot_prediction_sequence", "main"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _extent(model: PredictionModel) -> list[float]:
    g = model.grid
    return [g.min[0], g.min[0] + g.dims[0] * g.resolution, g.min[1], g.min[1] + g.dims[1] * g.resolution]


def _scene_top(ax, scene: Scene) -> None:
    for box in scene.boxes:
        lo, hi = box.lower, box.upper
        ax.plot([lo[0], hi[0], hi[0], lo[0], lo[0]], [lo[1], lo[1], hi[1], hi[1], lo[1]], color="saddlebrown", lw=1)
    for cup in scene.cups:
        ax.add_patch(__import__("matplotlib").patches.Circle(cup.position[:2], cup.radius, fill=False, color="green",
                                                            lw=1.5))
    ax.set_xlim(-0.7, 1.0)
    ax.set_ylim(-1.8, -0.3)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)


def _skeleton_top(ax, human: HumanModel, placed: np.ndarray, color: str = "black") -> None:
    ends, _ = human.capsules(placed)
    for seg in ends:
        ax.plot(seg[:, 0], seg[:, 1], color=color, lw=1.5)


def plot_swept_volumes(model: PredictionModel, scene: Scene, library: MotionLibrary | None, path: str | Path) -> Path:
    """One top-view panel per class (see the module docstring).

    Voxels shared by every class's volume (mostly the body) are grey; the class's own voxels are
    coloured by how many of the M volumes contain them (few: specific to this class). A volume of
    probabilities (``demos``, ``spread``, ``timed``) is drawn by its support, the voxels with p > 0.
    """
    plt = _plt()
    human = HumanModel()
    m = model.n_classes
    cols = min(4, m)
    rows = (m + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), dpi=100, squeeze=False)
    volumes = model.require_volumes("the swept-volume plot") > 0  # (M, nx, ny, nz) bool: each class's support
    share = volumes.sum(axis=0)                                         # (nx, ny, nz) classes per voxel
    ext = _extent(model)
    for c in range(m):
        ax = axes.flat[c]
        vol = volumes[c]
        common = np.any(vol & (share == m), axis=2)
        own = np.where(vol, share, m + 1).min(axis=2).astype(float)     # fewest sharing classes over z
        own[own > m] = np.nan
        ax.imshow(np.where(common, 1.0, np.nan).T, origin="lower", extent=ext, cmap="Greys", vmin=0, vmax=2.5,
                  interpolation="nearest")
        ax.imshow(np.where(common, np.nan, own).T, origin="lower", extent=ext, cmap="plasma", vmin=1, vmax=m,
                  interpolation="nearest", alpha=0.85)
        mot = model.motion(c)
        placed = place_in_scene(mot, mot[0], scene)
        hand = human.hand_position(placed)
        _skeleton_top(ax, human, placed[0])
        ax.plot(hand[:, 0], hand[:, 1], color="cyan", lw=1.5)
        if library is not None:
            mapping = require_mapping(library.feature_names, "the reach points of the swept-volume plot",
                                      f"library {library.source}")
            demos = [mapping.to_human(d.features) for d in library.by_class(c)]
            reach, _ = reach_points(human, demos, scene)
            ends = np.array([human.hand_position(place_in_scene(f, f[0], scene))[-1] for f in demos])
            ax.scatter(ends[:, 0], ends[:, 1], color="orange", marker="x", s=8, lw=0.8, zorder=5)
            ax.scatter(reach[:, 0], reach[:, 1], color="red", s=6, zorder=6)
        _scene_top(ax, scene)
        ax.set_title(f"{c}: {model.class_names[c]} ({int(vol.sum())} voxels)", fontsize=9)
    for ax in axes.flat[m:]:
        ax.axis("off")
    fig.suptitle(f"swept volumes seen from above ({model.grid.resolution:g} m voxels). grey: in every class's "
                 "volume; colour: number of classes sharing the voxel (dark = this class only);\ncyan: regressed "
                 "hand path; red: the demonstrations' reach points (hand farthest from its start), "
                 "orange x: their final hand positions; black: first regressed posture",
                 fontsize=9)
    fig.tight_layout()
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p)
    plt.close(fig)
    return p


def plot_prediction_sequence(model: PredictionModel, scene: Scene, features: np.ndarray, true_class: int,
                             path: str | Path, fractions: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.6, 0.8),
                             title: str = "") -> Path:
    """Predicted occupancy at several executed fractions of one demonstration (paper Fig. 3), from above.

    Each panel shows, per (x, y) column, the largest p(x|xi) over the voxels above the table top
    (blue low, red high), the current posture and the class posteriors.
    """
    plt = _plt()
    human = HumanModel()
    core = PredictorCore(model, scene)
    core.reset(0)
    n = len(features)
    stops = {max(1, int(round(f * n))): f for f in fractions}
    snaps = []
    for i, f in enumerate(features):
        res = core.update(f, i)
        if i + 1 in stops:
            snaps.append((stops[i + 1], res, place_in_scene(f, features[0], scene)))
    table_top = max((b.upper[2] for b in scene.boxes), default=model.grid.min[2])
    k0 = int(np.clip(np.floor((table_top - model.grid.min[2]) / model.grid.resolution), 0, model.grid.dims[2] - 1))
    cols = min(3, len(snaps))
    rows = (len(snaps) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.3 * cols, 4.1 * rows), dpi=100, squeeze=False)
    ext = _extent(model)
    im = None
    for k, (frac, res, placed) in enumerate(snaps):
        ax = axes.flat[k]
        top = res.occupancy[:, :, k0:].max(axis=2)
        im = ax.imshow(np.where(top > 0, top, np.nan).T, origin="lower", extent=ext, cmap="coolwarm", vmin=0, vmax=1,
                       interpolation="nearest")
        _skeleton_top(ax, human, placed)
        _scene_top(ax, scene)
        order = np.argsort(res.posterior)[::-1][:2]
        post = ", ".join(f"{model.class_names[j]} {res.posterior[j]:.2f}" for j in order)
        ax.set_title(f"{frac * 100:.0f}% executed (true: {model.class_names[true_class]})\n{post}", fontsize=8)
    for ax in axes.flat[len(snaps):]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=list(axes.flat), shrink=0.6, label="max p(x | xi) above the table")
    fig.suptitle(title or "predicted workspace occupancy while the motion is observed", fontsize=9)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p)
    plt.close(fig)
    return p


def main(argv: list[str] | None = None, prog: str = "python -m services.predictor.plots") -> int:
    """Write the two PNGs; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="models/model.npz", help="model file (default: models/model.npz)")
    parser.add_argument("--library", default=None, help="library for the reach points and the observed "
                        "demonstration (default: the synthetic library, seed 0)")
    parser.add_argument("--scene", default=None, help="scene file (default: the embedded pr2_two_cups)")
    parser.add_argument("--demo", type=int, default=0, help="index (in the library) of the demonstration observed "
                        "in the prediction sequence (default 0)")
    parser.add_argument("--heldout-seed", type=int, default=None, help="observe held-out demonstration --demo of "
                        "heldout_split(library, 1, SEED) (train the model with --heldout 1 --seed SEED)")
    parser.add_argument("--out-dir", default="runs/plots", help="where to write the PNGs (default runs/plots)")
    args = parser.parse_args(argv)
    with cli_errors(prog):
        model = PredictionModel.load(args.model)
        scene = load_scene(args.scene)
        lib = load_library(args.library) if args.library else default_library()
        out = Path(args.out_dir)
        print(plot_swept_volumes(model, scene, lib, out / "swept_volumes.png"))
        pool = lib.demos if args.heldout_seed is None else heldout_split(lib, 1, args.heldout_seed)[1]
        d = pool[args.demo % len(pool)]
        print(plot_prediction_sequence(model, scene, d.features, d.label, out / "prediction_sequence.png",
                                       title=f"predicted occupancy while observing {d.source} "
                                             f"(class {d.class_name})"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
