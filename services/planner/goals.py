"""Planning goals: grasp poses at the scene's cups turned into PR2 goal configurations by IK.

A task-space goal is a list of candidate gripper poses (world frame, the ``r_gripper_tool_frame``);
the first feasible one wins. For a cup, the candidates are the pre-grasp poses of
:func:`services.planner.grasps.grasp_candidates` (side and/or top approaches). All candidates of all
goals are solved in ONE batched IK call (pytorch-kinematics, several seeds each, torso held at the
start lift); a solution is kept when it
converged, lies within the joint limits and is collision-free (static scene + self-collision). Among
those the one closest to the start configuration is chosen. Goals that fail are reported (with
the reason) and marked invalid, never silently replaced: outside the scene's workspace, beyond the
arm's reach, IK failure, or every IK solution in collision. Joint-space goals may be given directly.

``python -m services.planner.goals [--scene S] [--plot PNG]`` prints the goals of a scene and draws
the robot at the start and goal configurations (top and side views).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from shared.arguments import ArgumentParser
from shared.robot import PR2
from shared.scene import Cup, Scene, load_scene

from .costs import CostConfig, StateCost
from .grasps import GraspConfig, grasp_candidates

__all__ = ["IKGoals", "cup_goals", "pose_goals", "joint_goals", "plot_scene", "main"]



@dataclass
class IKGoals:
    """K goals as configurations (``services.planner.core.GoalSet`` takes names, q, valid, reasons).

    Attributes:
        names: K goal names.
        q: ``(K, D)`` goal configurations, always within the limits (the start where invalid).
        valid: ``(K,)`` bool.
        reasons: K strings, why a goal is invalid ("" when valid).
        poses: ``(K, 4, 4)`` world pose of the chosen target (NaN where none).
        labels: K strings, which candidate was chosen (e.g. "side yaw -25 pitch 0").
        clearance: ``(K,)`` smallest sphere clearance to the static obstacles at ``q`` (m; NaN if invalid).
    """

    names: list[str]
    q: torch.Tensor
    valid: torch.Tensor
    reasons: list[str]
    poses: np.ndarray
    labels: list[str] = field(default_factory=list)
    clearance: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def summary(self) -> str:
        """One line per goal."""
        lines = []
        for i, n in enumerate(self.names):
            if bool(self.valid[i]):
                q = ", ".join(f"{v:+.3f}" for v in self.q[i].tolist())
                lines.append(f"{n}: OK ({self.labels[i]}), clearance {self.clearance[i]:.3f} m, q = [{q}]")
            else:
                lines.append(f"{n}: DROPPED: {self.reasons[i]}")
        return "\n".join(lines)


def _inside(box: Any, p: np.ndarray) -> bool:
    return bool(np.all(p >= box.min) and np.all(p <= box.max))


def pose_goals(names: Sequence[str], candidates: Sequence[Sequence[tuple[str, np.ndarray]]], robot: PR2,
               cost: StateCost, q_start: Any, scene: Scene | None = None, config: GraspConfig | None = None
               ) -> IKGoals:
    """Task-space goals (candidate tool poses per goal) -> goal configurations by batched IK.

    Args:
        names: K goal names.
        candidates: Per goal, ``[(label, (4, 4) world pose), ...]`` in preference order.
        robot: The PR2 (placed in the world).
        cost: State cost whose ``collision_free`` checks solutions.
        q_start: ``(D,)`` start configuration (seed of IK; its torso lift is kept).
        scene: When given, targets outside ``scene.workspace`` are dropped.
        config: IK settings.

    Returns:
        :class:`IKGoals` (invalid goals carry their reason).

    Raises:
        RobotModelError: ``q_start`` malformed or outside the joint limits.
    """
    config = config or GraspConfig()
    config.validate()
    q0 = robot.validate_configuration(q_start, what="start configuration")
    shoulder = robot.fk_links(q0)[2, :3, 3].double().cpu().numpy()
    k = len(names)
    reasons = [""] * k
    flat: list[tuple[int, str, np.ndarray]] = []
    for g, cands in enumerate(candidates):
        kept = []
        why = []
        for label, pose in cands:
            pose = np.asarray(pose, dtype=np.float64)
            if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
                why.append(f"{label}: not a finite (4, 4) pose")
            elif scene is not None and not _inside(scene.workspace, pose[:3, 3]):
                why.append(f"{label}: target {np.round(pose[:3, 3], 3).tolist()} outside the workspace")
            elif np.linalg.norm(pose[:3, 3] - shoulder) > config.max_reach:
                why.append(f"{label}: target {np.linalg.norm(pose[:3, 3] - shoulder):.2f} m from the shoulder "
                           f"(reach {config.max_reach} m)")
            else:
                kept.append((g, label, pose))
        if not kept:
            reasons[g] = "no candidate pose: " + ("; ".join(why[:2]) if why else "none given")
        flat.extend(kept)
    q_out = q0.expand(k, -1).clone()
    valid = torch.zeros(k, dtype=torch.bool, device=robot.device)
    poses = np.full((k, 4, 4), np.nan)
    labels = [""] * k
    clear = np.full(k, np.nan)
    per_goal = [[(lab, p) for gi, lab, p in flat if gi == g] for g in range(k)]
    tried = [0] * k
    ik_ok = [False] * k
    best_err = [math.inf] * k
    stage_size = len(config.yaw_offsets_deg)
    start = 0
    # stages of candidates in preference order; a goal stops at the first stage that gives a feasible solution
    while True:
        batch = [(g, lab, p) for g in range(k) if not bool(valid[g])
                 for lab, p in per_goal[g][start:start + stage_size]]
        if not batch:
            break
        start += stage_size
        targets = np.stack([p for _, _, p in batch])
        q, ok, ep, _ = robot.ik_solutions(targets, q0, n_seeds=config.n_seeds, seed=config.seed,
                                          pos_tolerance=config.pos_tolerance, rot_tolerance=config.rot_tolerance,
                                          max_iterations=config.max_iterations)
        feasible = ok & cost.collision_free(q, margin=config.min_clearance)  # (M, N)
        dist = torch.where(feasible, (q - q0).abs().sum(-1), torch.full_like(ep, math.inf))
        for g in range(k):
            rows = [i for i, (gi, _, _) in enumerate(batch) if gi == g]
            if not rows:
                continue
            tried[g] += len(rows)
            ik_ok[g] = ik_ok[g] or bool(ok[rows].any())
            best_err[g] = min(best_err[g], float(ep[rows].min()))
            d = dist[rows]
            if not bool(torch.isfinite(d).any()):
                continue
            r, n = divmod(int(torch.argmin(d.reshape(-1))), d.shape[1])
            q_out[g] = q[rows[r], n]
            valid[g] = True
            poses[g] = batch[rows[r]][2]
            labels[g] = batch[rows[r]][1]
    for g in range(k):
        if not bool(valid[g]) and tried[g]:
            reasons[g] = (f"every IK solution of {tried[g]} candidate poses is in collision" if ik_ok[g] else
                          f"IK failed for all {tried[g]} candidate poses (best position error {best_err[g]:.3f} m)")
    if bool(valid.any()):
        c = cost.clearance(q_out).double().cpu().numpy()
        clear = np.where(valid.cpu().numpy(), c, np.nan)
    return IKGoals(list(names), q_out, valid, reasons, poses, labels, clear)


def cup_goals(scene: Scene, robot: PR2, cost: StateCost | None = None, names: Sequence[str] | None = None,
              q_start: Any = None, config: GraspConfig | None = None) -> IKGoals:
    """A pre-grasp goal configuration at each named cup of ``scene`` (default: every cup).

    Args:
        scene: The scene (cups, workspace).
        robot: The PR2 placed at the scene's base pose.
        cost: Collision checker (default: ``StateCost.from_scene``).
        names: Cup names (unknown names raise ``SceneError``).
        q_start: Start configuration (default: ``robot.q_start``).
        config: Grasp and IK settings.

    Returns:
        :class:`IKGoals` in ``names`` order.
    """
    config = config or GraspConfig()
    cost = cost or StateCost.from_scene(scene, robot, CostConfig())
    if q_start is None:
        if robot.q_start is None:
            raise ValueError("cup_goals needs q_start (the scene has no [robot] start_arm)")
        q_start = robot.q_start
    names = list(names) if names else [c.name for c in scene.cups]
    cups = [scene.cup(n) for n in names]
    if any(c.goal_arm is not None for c in cups):
        return _scene_or_ik_goals(scene, robot, cost, cups, q_start, config)
    q0 = robot.validate_configuration(q_start, what="start configuration")
    shoulder = robot.fk_links(q0)[2, :3, 3].double().cpu().numpy()
    cands = []
    for cup in cups:
        if not _inside(scene.workspace, cup.center):
            cands.append([(f"cup at {np.round(cup.center, 3).tolist()}", np.full((4, 4), np.nan))])
        else:
            cands.append(grasp_candidates(cup, shoulder, config))
    out = pose_goals(names, cands, robot, cost, q0, scene, config)
    for g, cup in enumerate(cups):
        if not _inside(scene.workspace, cup.center):
            out.reasons[g] = f"cup {cup.name} at {np.round(cup.center, 3).tolist()} is outside the workspace"
    return out


def _scene_or_ik_goals(scene: Scene, robot: PR2, cost: StateCost, cups: list[Cup], q_start: Any,
                       config: GraspConfig) -> IKGoals:
    """Cups with a ``goal_arm`` take that configuration (torso at the scene's lift); the others IK."""
    given = [c for c in cups if c.goal_arm is not None]
    lift = float(scene.robot.torso_lift)
    fixed = joint_goals([c.name for c in given], np.array([[lift, *c.goal_arm] for c in given]), robot, cost)
    fixed.labels = ["scene goal configuration"] * len(given)
    rest = [c.name for c in cups if c.goal_arm is None]
    ik = cup_goals(scene, robot, cost, names=rest, q_start=q_start, config=config) if rest else None
    order = [("fixed", given.index(c)) if c.goal_arm is not None else ("ik", rest.index(c.name)) for c in cups]
    parts = {"fixed": fixed, "ik": ik}
    pick = [(parts[src], i) for src, i in order]
    return IKGoals([g.names[i] for g, i in pick], torch.stack([g.q[i] for g, i in pick]),
                   torch.stack([g.valid[i] for g, i in pick]), [g.reasons[i] for g, i in pick],
                   np.stack([g.poses[i] for g, i in pick]), [g.labels[i] for g, i in pick],
                   np.array([g.clearance[i] for g, i in pick]))


def joint_goals(names: Sequence[str], q: Any, robot: PR2, cost: StateCost | None = None) -> IKGoals:
    """Goals given directly as configurations ``q`` ``(K, D)``.

    A goal outside the joint limits, non-finite, or in collision (when ``cost`` is given) is invalid
    with its reason; its ``q`` is replaced by the limits-clamped value (finite rows) or the lower limits.
    """
    arr = np.asarray(q, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != robot.dof or arr.shape[0] != len(names):
        raise ValueError(f"joint-space goals must be (K, {robot.dof}) with K = {len(names)} names, got {arr.shape}")
    qt = torch.as_tensor(arr, device=robot.device, dtype=robot.dtype)
    finite = torch.isfinite(qt).all(-1)
    inside = robot.within_limits(torch.nan_to_num(qt)) & finite
    reasons = ["" if bool(v) else ("non-finite joint values" if not bool(f) else "outside the joint limits")
               for v, f in zip(inside, finite, strict=True)]
    qt = torch.where(finite[:, None], qt, robot.lower.expand_as(qt))
    qt = torch.minimum(torch.maximum(qt, robot.lower), robot.upper)
    valid = inside.clone()
    clear = np.full(len(names), np.nan)
    if cost is not None:
        free = cost.collision_free(qt)
        for i in range(len(names)):
            if bool(valid[i]) and not bool(free[i]):
                valid[i] = False
                reasons[i] = "goal configuration in collision"
        clear = np.where(valid.cpu().numpy(), cost.clearance(qt).double().cpu().numpy(), np.nan)
    poses = robot.end_effector(qt).double().cpu().numpy()
    return IKGoals(list(names), qt, valid, reasons, poses, ["joint space"] * len(names), clear)


# ----------------------------------------------------------------------------------------------
# picture


def plot_scene(scene: Scene, robot: PR2, configs: dict[str, Any], path: str | Path,
               targets: dict[str, np.ndarray] | None = None) -> Path:
    """Top (x-y) and side (x-z) views of the table, cups and the robot's spheres at ``configs``.

    Args:
        scene: The scene.
        robot: The placed PR2.
        configs: ``{label: (D,) configuration}``; each drawn in its own colour.
        path: PNG to write (parent directories are created).
        targets: Optional ``{label: (4, 4) pose}`` drawn as the tool point and approach arrow.

    Returns:
        The written path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(15, 6.5))
    colours = ["tab:blue", "tab:green", "tab:red", "tab:purple", "tab:orange", "tab:brown"]
    views = [(0, 1, "top view (x-y)", "y (m)"), (0, 2, "side view (x-z)", "z (m)")]
    for ax, (i, j, title, ylabel) in zip(axes, views, strict=True):
        for b in scene.boxes:
            ax.add_patch(Rectangle((b.lower[i], b.lower[j]), b.size[i], b.size[j], color="0.6", alpha=0.5,
                                   label=b.name))
        for cup in scene.cups:
            col = "blue" if "blue" in cup.name else "red" if "red" in cup.name else "k"
            if j == 1:
                ax.add_patch(Circle((cup.position[0], cup.position[1]), cup.radius, color=col, alpha=0.8))
            else:
                ax.add_patch(Rectangle((cup.position[0] - cup.radius, cup.position[2]), 2 * cup.radius,
                                       cup.height, color=col, alpha=0.8))
        hp = scene.human.pelvis_xyz
        ax.plot(hp[i], hp[j], "k*", ms=12, label="human pelvis")
        for c_i, (label, q) in enumerate(configs.items()):
            qt = torch.as_tensor(np.asarray(q, dtype=np.float64), dtype=robot.dtype, device=robot.device)
            centres = robot.sphere_centers(qt).double().cpu().numpy()
            radii = robot.sphere_radii.double().cpu().numpy()
            col = colours[c_i % len(colours)]
            order = np.argsort(centres[:, 3 - i - j])  # draw far spheres first
            for s in order:
                moving = robot.moving_slice.start <= s < robot.moving_slice.stop
                ax.add_patch(Circle((centres[s, i], centres[s, j]), radii[s], fill=moving, alpha=0.18 if moving
                                    else 0.5, ec=col, fc=col, lw=0.6))
            tool = robot.end_effector(qt).double().cpu().numpy()[:3, 3]
            ax.plot(tool[i], tool[j], "o", color=col, ms=5, label=label)
        for t in (targets or {}).values():
            if np.all(np.isfinite(t)):
                ax.annotate("", xy=(t[i, 3] + 0.08 * t[i, 0], t[j, 3] + 0.08 * t[j, 0]), xytext=(t[i, 3], t[j, 3]),
                            arrowprops={"arrowstyle": "->", "color": "k"})
        ax.set_title(title)
        ax.set_xlabel("x (m)")
        ax.set_ylabel(ylabel)
        ax.set_aspect("equal")
        ax.set_xlim(-1.0, 1.5)
        ax.set_ylim((-1.6, 0.3) if j == 1 else (0.0, 1.6))
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(f"{scene.name}: PR2 spheres (filled: moving; outlined: fixed base) and the cups")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None, prog: str = "python -m services.planner.goals") -> int:
    """Print the cup goals of a scene (IK) and optionally draw them."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default=None, help="scene file or embedded name (default pr2_two_cups)")
    parser.add_argument("--approach", default="any", choices=("side", "top", "any"))
    parser.add_argument("--plot", default=None, help="PNG of the start and goal configurations")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    scene = load_scene(args.scene)
    robot = PR2.from_scene(scene)
    cost = StateCost.from_scene(scene, robot)
    goals = cup_goals(scene, robot, cost, config=GraspConfig(approach=args.approach))
    print(goals.summary())
    for i, n in enumerate(goals.names):
        if bool(goals.valid[i]):
            got = robot.end_effector(goals.q[i]).double().cpu().numpy()
            print(f"{n}: tool position error {np.linalg.norm(got[:3, 3] - goals.poses[i][:3, 3]) * 1e3:.2f} mm")
    if args.plot:
        configs = {"start": robot.q_start}
        configs.update({f"goal {n}": goals.q[i] for i, n in enumerate(goals.names) if bool(goals.valid[i])})
        targets = {n: goals.poses[i] for i, n in enumerate(goals.names)}
        print(f"wrote {plot_scene(scene, robot, configs, args.plot, targets)}")
    return 0 if bool(goals.valid.all()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
