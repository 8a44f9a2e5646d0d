"""Where a library's hands reach, drawn in a scene: ``python -m tools.reach LIBRARY --out PNG``.

:func:`plot_reach_points` draws a top view (table, cups, the human's pelvis and heading, one dot per
demonstration's reach point coloured by class); ``foresight library generate --plot`` uses it too.
The command prints each class's mean reach point and spread, a check of the human model's
conventions on a recorded library (docs/human-model.md).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from shared.arguments import ArgumentParser
from shared.feature_sets import require_mapping
from shared.human import HumanModel, reach_points
from shared.library import load_library
from shared.runtime import UserError, cli_errors, help_text
from shared.scene import load_scene

from .png import check_png

__all__ = ["plot_reach_points", "main"]


def plot_reach_points(reach: np.ndarray, labels: np.ndarray, scene, path, title: str = "",
                      goals: np.ndarray | None = None) -> None:
    """Top view PNG: table, cups, the human's pelvis and heading, reach points coloured by class.

    Args:
        reach: ``(N, 3)`` scene-frame hand positions.
        labels: ``(N,)`` class of each.
        scene: The scene they are placed in.
        path: Output PNG.
        title: Figure title.
        goals: Optional ``(M, 3)`` scene-frame goal positions, drawn as crosses.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 6))
    for b in scene.boxes:
        ax.add_patch(plt.Rectangle(tuple(b.lower[:2]), b.size[0], b.size[1], fill=False, lw=1.5,
                                   label=f"{b.name} (top z={b.upper[2]:.2f})"))
    for c in scene.cups:
        colour = c.name.split("_")[0] if c.name.split("_")[0] in ("red", "blue", "green") else "grey"
        ax.add_patch(plt.Circle(tuple(c.position[:2]), c.radius, color=colour, alpha=0.6, label=c.name))
    px, yaw = scene.human.pelvis_xyz, scene.human.pelvis_yaw
    ax.plot(px[0], px[1], "ks", ms=8, label="human pelvis")
    ax.annotate("", xy=(px[0] + 0.25 * math.cos(yaw), px[1] + 0.25 * math.sin(yaw)), xytext=(px[0], px[1]),
                arrowprops={"arrowstyle": "->", "lw": 2})
    labels = np.asarray(labels)
    cmap = plt.get_cmap("tab10")
    for m in np.unique(labels):
        p = reach[labels == m]
        ax.scatter(p[:, 0], p[:, 1], s=14, color=cmap(int(m) % 10),
                   label=f"class {int(m)} (z {p[:, 2].mean():.2f})")
        if goals is not None:
            ax.plot(goals[m, 0], goals[m, 1], "x", color=cmap(int(m) % 10), ms=12, mew=2.5)
    ax.set_aspect("equal")
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m)")
    ax.set_title(title or "hand reach points, top view")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(alpha=0.3)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)


def main(argv: list[str] | None = None, prog: str = "python -m tools.reach") -> int:
    """``python -m tools.reach LIBRARY --out PNG``: plot a library's reach points placed in a scene.

    Prints each class's mean reach point and spread; the top view shows whether the model's
    conventions put the hand over the table (see docs/human-model.md).
    """
    parser = ArgumentParser(prog=prog, description=help_text(main.__doc__.splitlines()[0]))
    parser.add_argument("library", help="a directory of compound_*.csv or a .npz library")
    parser.add_argument("--scene", default=None, help="scene file or embedded name (default pr2_two_cups)")
    parser.add_argument("--out", default="runs/plots/human_goals.png", help="output PNG")
    args = parser.parse_args(argv)
    with cli_errors(prog):
        check_png(args.out, "--out")
        lib = load_library(args.library)
        if not lib.demos:
            raise UserError(f"library {lib.source}: no valid demonstration to draw ({len(lib.issues)} issue(s); "
                            f"`foresight library validate {args.library}` lists them)")
        mapping = require_mapping(lib.feature_names, prog, f"library {lib.source}")
        scene = load_scene(args.scene)
        reach, index = reach_points(HumanModel(), [mapping.to_human(d.features) for d in lib.demos], scene)
        labels = np.array([d.label for d in lib.demos])
        for m, name in enumerate(lib.class_names):
            r = reach[labels == m]
            if len(r):
                spread = np.linalg.norm(r - r.mean(axis=0), axis=1).mean()
                print(f"{m:>2} {name:<14} reach mean ({r[:, 0].mean():+.3f}, {r[:, 1].mean():+.3f}, "
                      f"{r[:, 2].mean():+.3f}) m  spread {spread:.3f} m  at sample {index[labels == m].mean():.0f}")
        plot_reach_points(reach, labels, scene, args.out, f"{lib.source}: hand at its reach point, in {scene.name}")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
