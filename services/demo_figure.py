"""The picture a demo run ends with: the robot's path around the predicted volume, the human, the chosen goals.

One PNG, three panels:

* top view of the scene: table and cups, the prediction planner's final predicted occupancy (the most
  probable voxel of each column), the human's hand path and body at the end, and each planner's
  executed end-effector path with a dot per replanning step coloured by the goal it chose;
* the clearance between the robot and the real human over time, per planner (below 0: contact);
* the goal each planner chose at every replanning step;

titled by :func:`figure_title` (the reach, the scene, the robot's pace, the run's length).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from services.demo_outcome import Outcome
from services.experiments.plots import save_figure
from shared.protocol import HumanPose, OccupancyGrid
from shared.scene import Scene

if TYPE_CHECKING:
    from services.demo import DemoConfig
    from services.scenario import Summary

__all__ = ["draw_outcomes", "poses_of_the_run"]

_PLANNER_COLORS = ("#2a9d3a", "#8a5cc2", "#7f7f7f", "#d08c1a")
_GOAL_COLORS = {"blue": "#2659f2", "red": "#e62626", "green": "#1ab233", "yellow": "#e6cc1a"}


def _goal_color(name: str) -> str:
    return next((c for word, c in _GOAL_COLORS.items() if word in name.lower()), "#444444")


def _hand_path(poses: list[HumanPose], scene: Scene) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """``(P, 3)`` the human's hand over the run and the body capsules at its last pose (scene frame)."""
    if not poses:
        return np.zeros((0, 3)), None
    from shared.human import HumanModel, place_in_scene

    model = HumanModel()
    first = poses[0].features
    placed = [place_in_scene(p.features, first, scene) for p in poses]
    hands = np.array([model.hand_position(f) for f in placed])
    ends, radii = model.capsules(placed[-1])
    return hands, (np.asarray(ends), np.asarray(radii))


def poses_of_the_run(poses: list[HumanPose], outcomes: list[Outcome]) -> list[HumanPose]:
    """The poses up to the last robot state of any run (all of them when there is none).

    An interrupted run's replayer went on while the services stopped, and its figure drew the whole reach (a review:
    the hand at the cup in a run cut short at 1.35 s).
    """
    ends_at = max((float(o.stamps[-1]) for o in outcomes if len(o.stamps)), default=None)
    return poses if ends_at is None else [p for p in poses if p.stamp <= ends_at + 1e-9]


def _seconds(o: Outcome) -> np.ndarray:
    """The states' times from the run's first state (s): a real-time run stamps the wall clock, lock-step from 0."""
    return o.stamps - o.stamps[0] if len(o.stamps) else o.stamps


def _unit_words(outcomes: list[Outcome]) -> str:
    """What the goal lane's marks are: ``replanning step`` (lock-step) or ``plan`` (a real-time run's)."""
    unit = outcomes[0].unit if outcomes else "step"
    return "replanning step" if unit == "step" else unit


def _step_points(o: Outcome, period_s: float) -> np.ndarray:
    """The end-effector position when each plan of ``o.chosen_goal_per_step`` was made (``(S, 3)``).

    At the plans' own times (``o.plan_t_s``) where the run has them: a real-time planner replans as soon as a
    new prediction comes, several times a period (its marks, one a period apart, piled up at the path's end);
    else one every ``period_s``.
    """
    steps = len(o.chosen_goal_per_step)
    if len(o.stamps) == 0:
        return np.zeros((0, 3))
    at = o.plan_t_s if o.plan_t_s is not None and len(o.plan_t_s) == steps else np.arange(steps) * period_s
    idx = np.searchsorted(_seconds(o), at, side="left").clip(0, len(o.stamps) - 1)
    return o.ee_path[idx]


def draw_outcomes(outcomes: list[Outcome], scene: Scene, prediction: OccupancyGrid | None,
                  poses: list[HumanPose], out: str | Path, period_s: float, title: str = "",
                  min_probability: float = 0.05) -> Path:
    """Draw the run(s) to a PNG; returns its path.

    Args:
        outcomes: One per planner run (the first is the prediction planner's).
        scene: The scene.
        prediction: The predicted occupancy drawn (the prediction planner's final one; None: none).
        poses: The human's poses during the run.
        out: PNG path.
        period_s: Seconds per replanning step (to mark the steps on the paths).
        title: Figure title.
        min_probability: Voxels below this are not drawn.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle
    from matplotlib.ticker import MaxNLocator

    fig = plt.figure(figsize=(15, 7.5))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.15, 1.0), height_ratios=(1.4, 1.0))
    top, clear, goals = fig.add_subplot(grid[:, 0]), fig.add_subplot(grid[0, 1]), fig.add_subplot(grid[1, 1])

    for b in scene.boxes:
        (x0, y0, _), (x1, y1, _) = b.lower, b.upper
        top.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="#d9b38c", edgecolor="#6b4a2a", alpha=0.5,
                                zorder=0))
    for cup in scene.cups:
        top.add_patch(Circle(tuple(cup.position[:2]), max(cup.radius, 0.03), color=_goal_color(cup.name), zorder=5))
        # above the robot's paths and marks, which hid it
        top.annotate(cup.name, cup.position[:2], xytext=(6, 6), textcoords="offset points", fontsize=9, zorder=9,
                     bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "alpha": 0.7, "linewidth": 0})
    if prediction is not None and prediction.indices.size:
        p = prediction.values.astype(np.float64) / 255.0
        keep = p >= min_probability
        ijk = np.stack(np.unravel_index(prediction.indices[keep].astype(np.int64),
                                        tuple(int(d) for d in prediction.dims)), -1)
        columns: dict[tuple[int, int], float] = {}
        for (i, j, _), v in zip(ijk, p[keep], strict=True):
            columns[(i, j)] = max(columns.get((i, j), 0.0), float(v))
        if columns:
            ij, v = np.array(list(columns)), np.array(list(columns.values()))
            o = np.argsort(v)
            sc = top.scatter(prediction.origin[0] + prediction.resolution * (ij[o, 0] + 0.5),
                             prediction.origin[1] + prediction.resolution * (ij[o, 1] + 0.5), c=v[o], cmap="YlOrRd",
                             vmin=0, vmax=1, marker="s", s=30, alpha=0.55, linewidths=0, zorder=1)
            fig.colorbar(sc, ax=top, shrink=0.6, label="predicted occupancy p(x|ξ), final (column max)")
    hands, body = _hand_path(poses_of_the_run(poses, outcomes), scene)
    if len(hands):
        top.plot(hands[:, 0], hands[:, 1], color="#333333", lw=1.5, ls="--", zorder=3, label="human's hand")
    if body is not None:
        ends, radii = body
        for i, ((a, b), r) in enumerate(zip(ends, radii, strict=True)):
            top.plot([a[0], b[0]], [a[1], b[1]], color="#b04a5a", lw=max(2.0, 120 * float(r)), alpha=0.8,
                     solid_capstyle="round", zorder=2, label="human's body at the run's end" if i == 0 else None)
    steps = max((len(o.chosen_goal_per_step) for o in outcomes), default=0)
    unit = _unit_words(outcomes)
    for k, o in enumerate(outcomes):
        col = _PLANNER_COLORS[k % len(_PLANNER_COLORS)]
        if len(o.ee_path):
            top.plot(o.ee_path[:, 0], o.ee_path[:, 1], color=col, lw=2.2, zorder=6,
                     label=f"robot hand, {o.planner} (contact {o.contact_s:.1f} s)")
            marks = _step_points(o, period_s)
            top.scatter(marks[:, 0], marks[:, 1], c=[_goal_color(g) for g in o.chosen_goal_per_step], s=22,
                        edgecolors=col, linewidths=0.8, zorder=7)
            # where the hand starts and ends (a review could not tell the path's direction)
            top.scatter(*o.ee_path[0, :2], marker="o", s=70, facecolors="white", edgecolors=col, linewidths=1.8,
                        zorder=8)
            top.scatter(*o.ee_path[-1, :2], marker="X", s=80, color=col, zorder=8)
            clear.plot(_seconds(o), o.clearance, color=col, lw=1.8, label=o.planner)
        goals.scatter(np.arange(len(o.chosen_goal_per_step)), np.full(len(o.chosen_goal_per_step), k),
                      c=[_goal_color(g) for g in o.chosen_goal_per_step], s=70, marker="s")
    top.set_aspect("equal")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.set_title(f"top view: robot hand paths\n(dots: the hand at each {unit}, in the chosen cup's colour)",
                  fontsize=10)
    if any(len(o.ee_path) for o in outcomes):  # the start and end marks, in each planner's colour
        top.scatter([], [], marker="o", s=70, facecolors="white", edgecolors="k", linewidths=1.8,
                    label="robot hand's start")
        top.scatter([], [], marker="X", s=80, color="k", label="robot hand's end")
    if top.get_legend_handles_labels()[0]:  # under the view: inside, "best" still lay on the paths and the cups
        top.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8, frameon=False)
    clear.axhline(0.0, color="k", lw=0.8)
    clear.set_ylabel("robot-human clearance (m)")
    clear.set_xlabel("t (s)")
    clear.set_title("clearance to the real human (below 0: contact)", fontsize=10)
    if clear.get_legend_handles_labels()[0]:  # a run with no robot state draws no line
        clear.legend(fontsize=8)
    goals.set_yticks(range(len(outcomes)), [o.planner for o in outcomes])
    goals.xaxis.set_major_locator(MaxNLocator(nbins=min(max(steps, 1), 20), integer=True))  # 30 plans: unreadable
    goals.set_xlabel(unit + ("" if unit == "replanning step" else " (a real-time planner replans as each prediction "
                             "comes)"))
    goals.set_title(f"goal chosen at each {unit} (square colour = cup)", fontsize=10)
    goals.set_ylim(-0.6, len(outcomes) - 0.4)
    if title:
        fig.suptitle(_wrapped(title, fig.get_figwidth(), 11), fontsize=11)
    return save_figure(fig, out)


def _wrapped(title: str, width_in: float, fontsize: float, lines: int = 3) -> str:
    """``title`` in lines that fit a figure ``width_in`` inches wide, at most ``lines`` of them.

    One line ran off both edges (a ``--compare`` run cut short: 203 characters on a 15-inch figure); a character
    of the title's font is taken as 0.62 of its size, a little wider than its average.
    """
    import textwrap

    return "\n".join(textwrap.wrap(title, max(20, int(width_in * 72 / (0.62 * fontsize))), max_lines=lines,
                                   placeholder=" ..."))


def figure_title(cfg: DemoConfig, summary: Summary, scene: str, cut: str = "") -> str:
    """The run's PNG title: the human's reach, the scene, the robot's pace and the run's length.

    A real-time run's length is its wall time and its plans (the planner replans as each prediction comes: 100
    plans in 10 s, where the title said "20 steps of 0.5 s"), the prediction planner's in a ``--compare`` run;
    ``cut``: how a planner's run was cut short.
    """
    wall, reached = cfg.run_s, summary.reached_t_s
    more = (f", then on to its goal at {reached:.1f} s" if cfg.finish_s and reached is not None and reached > wall
            else "")
    length = (f"{cfg.steps} steps of {cfg.period_s:g} s" if cfg.mode == "lockstep" else
              f"{wall:g} s in real time{more}, {len(summary.chosen_goal_per_step)} plans"
              + (" (the prediction planner's)" if cfg.compare else ""))  # the others' are their own
    return (f"foresight demo: {summary.human_class} reach, scene {scene}, robot at {cfg.robot_speed:g} of its velocity "
            f"limits, {length}" + (f": the {cut}" if cut else ""))
