"""``foresight bench planner --plot PNG``: plan around a synthetic occupancy blob and draw the paths."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch

from shared.scene import load_scene

from .bench import blob_occupancy
from .core import Planner, PlannerConfig

__all__ = ["plot_blob"]


def _box_edges(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(corners[a] != corners[b]) == 1]
    return [corners[[a, b]] for a, b in pairs]


def plot_blob(path: str, config: PlannerConfig | None = None, center: tuple[float, float, float] | None = None,
              steps: int = 1) -> dict[str, Any]:
    """Plan for the scene's goals around a synthetic blob and draw the end-effector paths (PNG).

    Three panels: top view (x-y), side view (x-z) and 3-D; the optimised paths (solid), the straight
    lines they started from (dashed), the blob (voxels with p > 0.3), the table and the cups.

    Returns:
        Per-goal human cost of the straight lines and of the optimised trajectories.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    config = config or PlannerConfig()
    scene = load_scene()
    planner = Planner(scene, config)
    occ = blob_occupancy(scene, center)
    q0 = planner.robot.q_start.double().cpu().numpy()
    res = planner.step(q0, occ)
    for _ in range(steps - 1):
        res = planner.step(res.start, occ)
    dev, dt = planner.device, planner.dtype
    trajs = torch.as_tensor(res.trajectories, device=dev, dtype=dt)
    from .multigoal import init_straight_lines

    lines = init_straight_lines(trajs[:, 0], trajs[:, -1], trajs.shape[1])
    t_opt, t_line = planner.cost_terms(trajs), planner.cost_terms(lines)
    ee = planner.robot.end_effector(trajs)[..., :3, 3].cpu().numpy()  # (K, T, 3)
    ee_line = planner.robot.end_effector(lines)[..., :3, 3].cpu().numpy()
    blob = scene.grid.centers()[occ > 0.3]
    fig = plt.figure(figsize=(16, 5.5))
    axes = [fig.add_subplot(1, 3, 1), fig.add_subplot(1, 3, 2), fig.add_subplot(1, 3, 3, projection="3d")]
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown", "tab:pink", "tab:gray"]
    for ax, (i, j), title in zip(axes[:2], [(0, 1), (0, 2)], ["top view (x-y)", "side view (x-z)"], strict=True):
        ax.scatter(blob[:, i], blob[:, j], s=4, c="orange", alpha=0.15, label="occupancy p > 0.3")
        for b in scene.boxes:
            ax.add_patch(plt.Rectangle((b.lower[i], b.lower[j]), b.size[i], b.size[j], fill=False, color="k",
                                       label=b.name))
        for cup in scene.cups:
            ax.add_patch(plt.Circle((cup.center[i], cup.center[j]), cup.radius, color="saddlebrown", alpha=0.7))
            ax.annotate(cup.name, (cup.center[i], cup.center[j]), fontsize=8, xytext=(4, 4), textcoords="offset points")
        for k in range(ee.shape[0]):
            col = colors[k % len(colors)]
            ax.plot(ee_line[k, :, i], ee_line[k, :, j], "--", color=col, alpha=0.6)
            ax.plot(ee[k, :, i], ee[k, :, j], "-o", ms=2, color=col,
                    label=f"{res.goal_names[k]}{' (chosen)' if k == res.chosen else ''}")
        ax.plot(ee[0, 0, i], ee[0, 0, j], "k*", ms=10, label="start")
        ax.set_xlabel("xyz"[i] + " (m)")
        ax.set_ylabel("xyz"[j] + " (m)")
        ax.set_aspect("equal")
        ax.set_title(title)
    axes[0].legend(fontsize=7, loc="best")
    ax3 = axes[2]
    ax3.scatter(blob[:, 0], blob[:, 1], blob[:, 2], s=3, c="orange", alpha=0.08)
    for b in scene.boxes:
        for e in _box_edges(b.lower, b.upper):
            ax3.plot(e[:, 0], e[:, 1], e[:, 2], "k-", lw=0.8)
    for cup in scene.cups:
        ax3.plot([cup.position[0]] * 2, [cup.position[1]] * 2, [cup.position[2], cup.position[2] + cup.height],
                 color="saddlebrown", lw=5)
    for k in range(ee.shape[0]):
        col = colors[k % len(colors)]
        ax3.plot(ee_line[k, :, 0], ee_line[k, :, 1], ee_line[k, :, 2], "--", color=col, alpha=0.6)
        ax3.plot(ee[k, :, 0], ee[k, :, 1], ee[k, :, 2], "-", color=col, lw=2)
    ax3.set_xlabel("x")
    ax3.set_ylabel("y")
    ax3.set_zlabel("z")
    ax3.set_title("3-D (dashed: straight lines in joint space)")
    human_line = t_line["human"].double().cpu().numpy()
    human_opt = t_opt["human"].double().cpu().numpy()
    fig.suptitle("STOMP around a predicted-occupancy blob: end-effector paths; human cost straight -> optimised: "
                 + ", ".join(f"{n} {a:.2f} -> {b:.3f}" for n, a, b in zip(res.goal_names, human_line, human_opt,
                                                                           strict=True)), fontsize=10)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"goal_names": res.goal_names, "human_straight": human_line.tolist(), "human_optimised": human_opt.tolist(),
            "chosen": res.chosen, "png": path}
