"""Pictures of the Table I experiment (the Fig. 9 picture is :func:`services.experiments.switch.plot_switch`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .heldout import short_name
from .interference import InterferenceResult
from .planners import VARIANTS

__all__ = ["plot_interference", "save_figure"]

COLOURS = {"basic": "tab:gray", "least_penetration": "tab:green", "current": "tab:orange"}


def plot_interference(result: InterferenceResult, path: str | Path) -> Path:
    """Table I as a picture: interference and clearance per demonstration and planner.

    Top: interference with the final prediction (mean and std over seeds); bottom: the minimum
    clearance to the real human, one dot per run.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(VARIANTS)
    x = np.arange(len(result.demos))
    width = 0.8 / len(names)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9.0, 6.5), sharex=True)
    for i, name in enumerate(names):
        mean, std = result.per_demo(name)  # the bar's std below it stops at 0: an interference is never negative
        ax1.bar(x + (i - 1) * width, mean, width, yerr=np.stack([np.minimum(std, mean), std]), color=COLOURS[name],
                label=VARIANTS[name].label, capsize=2)
        clear = result.values(name, "min_clearance")  # (demos, seeds)
        for j in range(len(result.demos)):
            ax2.scatter(np.full(clear.shape[1], x[j] + (i - 1) * width), clear[j], s=12, color=COLOURS[name])
    ax1.set_ylabel(f"interference with the\nfinal prediction ({result.unit(short=True)})")
    cfg = result.config
    ax1.set_title(f"Table I: {short_name(result.library)}, scene {cfg.scene}, robot -> {cfg.robot_cup}, "
                  f"human -> {cfg.human_cup}", fontsize=9)
    ax1.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the axes: over them, it hid runs
    ax2.axhline(0.0, color="k", lw=0.8)
    ax2.axhline(0.05, color="k", lw=0.6, ls=":")
    ax2.set_ylabel("min clearance to the\nreal human (m)")
    ax2.set_xticks(x, [f"#{d}" for d in result.demos])
    ax2.set_xlabel("held-out demonstration")  # the colours are the legend's above
    return save_figure(fig, path)


def save_figure(fig: Any, path: str | Path) -> Path:
    """Lay out, write (110 dpi PNG, creating the folder) and close a matplotlib figure; returns the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
