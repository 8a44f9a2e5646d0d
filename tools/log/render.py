"""``foresight log render``: draw a replanning step of a logged run with matplotlib.

Table, cups, the human's body, the occupied voxels coloured by probability, the robot's collision
spheres and the K candidate end-effector paths, the chosen one highlighted, as a 3D view and a top
view (:func:`render_step`, one PNG per step).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from shared.atomic_file import make_parent
from shared.foxglove.scene import ArmModel
from shared.scene import Scene

from .steps import StepView, step_title

__all__ = ["render_step"]


_GOAL_COLORS = {"blue": "#2659f2", "red": "#e62626", "green": "#1ab233", "yellow": "#e6cc1a"}


def _goal_color(name: str, k: int) -> str:
    for word, col in _GOAL_COLORS.items():
        if word in name.lower():
            return col
    return ["#1f77b4", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2"][k % 5]


def _robot_geometry(view: StepView, scene: Scene, robot: ArmModel) -> tuple[np.ndarray | None, np.ndarray | None,
                                                                        np.ndarray | None]:
    """(sphere centres (S,3), radii (S,), end-effector paths (K,T,3)) from the robot model."""
    import torch

    names = list(robot.joint_names)

    def order(q: np.ndarray, msg_names: list[str]) -> np.ndarray:
        return q[..., [list(msg_names).index(n) for n in names]]

    def tens(q: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(q, dtype=robot.lower.dtype, device=robot.lower.device)

    centers = radii = None
    if view.state is not None and sorted(view.state.joint_names) == sorted(names):
        centers = robot.sphere_centers(tens(order(view.state.q, view.state.joint_names))).detach().cpu().numpy()
        radii = robot.sphere_radii.detach().cpu().numpy()
    paths = None
    if sorted(view.plan.joint_names) == sorted(names):
        q = order(view.plan.trajectories.astype(np.float64), view.plan.joint_names)
        paths = robot.end_effector(tens(q)).detach().cpu().numpy()[..., :3, 3]
    return centers, radii, paths


def _human_geometry(view: StepView, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    if view.pose is None:
        return None
    from shared.human import HumanModel, place_in_scene

    first = view.first_pose.features if view.first_pose is not None else view.pose.features
    feats = place_in_scene(view.pose.features, first, scene)
    ends, radii = HumanModel().capsules(feats)
    return np.asarray(ends), np.asarray(radii)


def render_step(view: StepView, scene: Scene, out: str | Path, robot: ArmModel | None = None,
                min_probability: float = 0.05, dpi: int = 110) -> Path:
    """Draw one replanning step (3D view and top view) to a PNG.

    Args:
        view: The step's messages.
        scene: The scene (table, cups).
        out: PNG path (parent directories are created).
        robot: Robot model for the spheres and end-effector paths (default: shared.robot.PR2 in the scene).
        min_probability: Voxels below this are not drawn.
        dpi: Resolution.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if robot is None:
        import torch

        from shared.robot import PR2

        robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    plan = view.plan
    centers, radii, paths = _robot_geometry(view, scene, robot)
    human = _human_geometry(view, scene)

    fig = plt.figure(figsize=(15, 7.2))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    lo = np.array([-1.0, -2.0, 0.0])
    hi = np.array([1.4, 0.4, 2.0])
    lo, hi = np.minimum(lo, scene.grid.min), np.maximum(hi, scene.grid.max)

    # table and other boxes
    for b in scene.boxes:
        x0, y0, z0 = b.lower
        x1, y1, z1 = b.upper
        top = [[(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]]
        ax3.add_collection3d(Poly3DCollection(top, facecolor="#b08050", alpha=0.35, edgecolor="#6b4a2a"))
        ax2.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="#d9b38c", edgecolor="#6b4a2a", alpha=0.6,
                                zorder=0, label=b.name))
    # cups
    for k, cup in enumerate(scene.cups):
        col = _goal_color(cup.name, k)
        th = np.linspace(0, 2 * np.pi, 24)
        for z in (cup.position[2], cup.position[2] + cup.height):
            ax3.plot(cup.position[0] + cup.radius * np.cos(th), cup.position[1] + cup.radius * np.sin(th),
                     np.full_like(th, z), color=col, lw=1.5)
        ax2.add_patch(Circle(tuple(cup.position[:2]), cup.radius, color=col, zorder=4, label=cup.name))

    # occupancy
    occ = view.occupancy
    if occ is not None:
        p = occ.values.astype(np.float64) / 255.0
        keep = p >= min_probability
        ijk = np.stack(np.unravel_index(occ.indices[keep].astype(np.int64), tuple(int(d) for d in occ.dims)), -1)
        c = occ.origin + occ.resolution * (ijk + 0.5)
        pk = p[keep]
        order = np.argsort(pk)
        if c.size:
            ax3.scatter(c[order, 0], c[order, 1], c[order, 2], c=pk[order], cmap="YlOrRd", vmin=0, vmax=1,
                             s=10, alpha=0.25, depthshade=False, linewidths=0)
            # top view: the most probable voxel of each (x, y) column
            cols: dict[tuple[int, int], float] = {}
            for (i, j, _), v in zip(ijk, pk, strict=True):
                cols[(i, j)] = max(cols.get((i, j), 0.0), v)
            ij = np.array(list(cols))
            v = np.array(list(cols.values()))
            o = np.argsort(v)
            ax2.scatter(occ.origin[0] + occ.resolution * (ij[o, 0] + 0.5),
                        occ.origin[1] + occ.resolution * (ij[o, 1] + 0.5), c=v[o], cmap="YlOrRd", vmin=0,
                        vmax=1, marker="s", s=28, alpha=0.6, linewidths=0, zorder=1)
            from matplotlib.cm import ScalarMappable
            from matplotlib.colors import Normalize

            fig.colorbar(ScalarMappable(Normalize(0, 1), "YlOrRd"), ax=ax2, shrink=0.7,
                         label="predicted occupancy p(x|ξ) (top view: column max)")

    span = float(np.max(hi - lo))
    pts_per_m = 0.45 * 7.2 * 72 / span  # rough size of a metre in points in the 3D view
    # human body: capsules (3D: thick lines; top view: the capsules' footprints)
    if human is not None:
        ends, hr = human
        for (a, b_), r in zip(ends, hr, strict=True):
            ax3.plot(*zip(a, b_, strict=True), color="#3060d0", lw=max(1.5, 2 * r * pts_per_m), alpha=0.6,
                     solid_capstyle="round")
            for s in np.linspace(0.0, 1.0, 6):
                c = a + s * (b_ - a)
                ax2.add_patch(Circle((c[0], c[1]), r, facecolor="#3060d0", edgecolor="none", alpha=0.18,
                                     zorder=3))
            ax2.plot([a[0], b_[0]], [a[1], b_[1]], color="#1a3a90", lw=1.2, zorder=3)
        ax2.plot([], [], color="#3060d0", lw=4, label="human body")

    # robot spheres
    if centers is not None and radii is not None:
        ax3.scatter(centers[:, 0], centers[:, 1], centers[:, 2], s=(2 * radii * pts_per_m) ** 2,
                    color="#8a8a9a", alpha=0.35, edgecolors="#555", linewidths=0.3)
        for cc, r in zip(centers, radii, strict=True):
            ax2.add_patch(Circle(tuple(cc[:2]), r, facecolor="#9a9aaa", edgecolor="#555", alpha=0.25, lw=0.3,
                                 zorder=2))
        ax2.plot([], [], "o", color="#9a9aaa", label="robot spheres")

    # candidate paths
    if paths is not None:
        for k in range(paths.shape[0]):
            chosen = k == plan.chosen
            col = "#10c040" if chosen else _goal_color(plan.goal_names[k], k)
            ls = "-" if chosen else ("--" if bool(plan.valid[k]) else ":")
            lw = 4.0 if chosen else 1.8
            label = (f"{plan.goal_names[k]}{' (chosen)' if chosen else ''}{'' if plan.valid[k] else ' (invalid)'}: "
                     f"cost {plan.cost_total[k]:.3g}")
            ax3.plot(paths[k, :, 0], paths[k, :, 1], paths[k, :, 2], ls, color=col, lw=lw, zorder=10)
            ax2.plot(paths[k, :, 0], paths[k, :, 1], ls, color=col, lw=lw, zorder=6, label=label)
            ax2.plot(paths[k, -1, 0], paths[k, -1, 1], "*", color=col, ms=12, zorder=7)
        ax3.scatter(*paths[0, 0], color="k", s=25)
        ax2.plot(paths[0, 0, 0], paths[0, 0, 1], "ko", ms=5, zorder=7, label="end effector now")

    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_zlim(lo[2], hi[2])
    ax3.set_box_aspect(tuple(hi - lo))
    ax3.view_init(elev=28, azim=-50)
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax2.set_xlim(lo[0], hi[0])
    ax2.set_ylim(lo[1], hi[1])
    ax2.set_aspect("equal")
    ax2.set_xlabel("x (m)")
    ax2.set_ylabel("y (m)")
    ax2.grid(alpha=0.3)
    ax2.legend(loc="upper left", fontsize=8, framealpha=0.85)
    fig.suptitle(step_title(view), fontsize=11)
    fig.tight_layout()
    out = make_parent(out)  # a file in the way named (mkdir said "File exists")
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out
