"""``foresight eval switch``: the paper's Fig. 8-9, over every demonstration of the human's class.

Protocol (section VI.C): the PR2 faces the human across the table and plans for both cups (K = 2);
the human reaches for the red cup. Two planners: the predicted occupancy (the paper's method) against
the current occupancy only. Each demonstration of the class is held out in turn (a model trained
without it) and run once per planner (seed ``seed``).

Per step, both candidates' integral cost (the Plan's ``cost_total``, evaluated at the end of the
step, Fig. 9) and the goal chosen. The *settle step* of a run is the step from which the robot keeps
its final goal to the end (0: it never changed its mind). A PNG like Fig. 9: two panels (current on
top, prediction below), one curve per candidate cup in its colour, every run thin, the median bold.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from services.executor.result import ExecutorResult
from shared.clearance import body_clearance
from shared.scene import load_scene

from .authors import FIG9_TRACES
from .harness import RunSpec, run_lockstep
from .heldout import (
    CupClass,
    HeldOutModels,
    human_class,
    human_file,
    load_experiment_library,
    samples_per_tick,
    short_name,
)
from .measures import contact_summary, postures_at
from .planners import Timing, build_planner
from .protocol import SWITCH_SCENE, authors_trial, move3d_path_weights, protocol, run_pacing, settings_run

__all__ = ["SWITCH_SCENE", "SwitchConfig", "SwitchRun", "SwitchResult", "settle_step", "away_step", "run_switch",
           "plot_switch"]


METHODS = ("prediction", "current")


def settle_step(chosen: list[str]) -> int | None:
    """First step from which every chosen goal equals the last one (None for an empty run)."""
    if not chosen:
        return None
    s = len(chosen) - 1
    while s > 0 and chosen[s - 1] == chosen[-1]:
        s -= 1
    return s


def away_step(chosen: list[str], human_cup: str) -> int | None:
    """First step from which the robot never again goes for the human's cup (the paper's "switch").

    Returns:
        The step (0: it never went for it), or None when the run ends going for the human's cup.
    """
    if not chosen or chosen[-1] == human_cup:
        return None
    last = max((i for i, g in enumerate(chosen) if g == human_cup), default=-1)
    return last + 1


def final_reached(result: ExecutorResult | None, goal_names: list[str], chosen: list[str]) -> int | None:
    """The step the run's final goal (``chosen[-1]``) was first reached, or None.

    Not the first goal reached: a robot that reached the blue cup at step 10 and turned to the red one at step 14
    was reported "red_cup, reached step 10".
    """
    if result is None or not chosen or chosen[-1] not in goal_names:
        return None
    return result.reached_steps.get(list(goal_names).index(chosen[-1]))


@dataclass(frozen=True)
class SwitchConfig:
    """Options of the Fig. 8-9 experiment (``demos`` 0: every demonstration of the class)."""

    library: str = "synthetic"
    scene: str = SWITCH_SCENE
    human_cup: str = "red_cup"
    demos: int = 0
    seed: int = 0
    timing: Timing = Timing()
    components: int | None = None
    w_human: float | None = None  # None: the planner's default
    volume: str | None = None  # None: the trainer's default
    methods: tuple[str, ...] = METHODS  # the occupancies compared (``eval volumes``: prediction only)
    protocol: str = "product"
    trials: str = "auto"  # authors: the authors' human motions; cup: the class nearest the human's cup; auto: the
    # authors' with the paper protocol on the paper's library, else cup
    models_dir: Path = Path("models/experiments")
    work_dir: Path = Path("runs/experiments")


@dataclass(frozen=True)
class SwitchRun:
    """One run: its demonstration, method, chosen goals and per-step costs of each candidate."""

    demo: int
    method: str
    goals: tuple[str, ...]
    goal_names: tuple[str, ...]
    cost_total: tuple[tuple[float, ...], ...]   # (steps, K)
    cost_human: tuple[tuple[float, ...], ...]   # (steps, K)
    settle_step: int | None
    away_step: int | None
    final_goal: str
    reached_step: int | None
    min_clearance: float
    time_in_contact: float
    planning_ms: float


@dataclass
class SwitchResult:
    """Every run of the experiment."""

    config: SwitchConfig
    library: str
    human: CupClass
    runs: list[SwitchRun] = field(default_factory=list)

    def settle(self, method: str) -> list[int | None]:
        """Settle step of each run of ``method``, in demonstration order."""
        return [r.settle_step for r in self.runs if r.method == method]

    def median_settle(self, method: str) -> float:
        """Median settle step of ``method`` (NaN without runs)."""
        v = [s for s in self.settle(method) if s is not None]
        return float(np.median(v)) if v else math.nan

    def away(self, method: str) -> list[int | None]:
        """:func:`away_step` of each run of ``method`` (None: it ended going for the human's cup)."""
        return [r.away_step for r in self.runs if r.method == method]

    def median_away(self, method: str) -> float:
        """Median away step of ``method``, a run that never left the human's cup counting as the run's length."""
        v = [self.config.timing.steps if s is None else s for s in self.away(method)]
        return float(np.median(v)) if v else math.nan

    def conflicts(self, method: str) -> int:
        """Runs of ``method`` that end going for the human's cup."""
        return sum(r.final_goal == self.config.human_cup for r in self.runs if r.method == method)

    def to_json(self) -> dict[str, Any]:
        """``switch_step_prediction``, ``switch_step_current`` (medians), per-run lists and the runs."""
        out: dict[str, Any] = {f"switch_step_{m}": self.median_settle(m) for m in METHODS}
        out.update({f"switch_steps_{m}": self.settle(m) for m in METHODS})
        out.update({f"away_step_{m}": self.median_away(m) for m in METHODS})
        out.update({f"away_steps_{m}": self.away(m) for m in METHODS})
        out.update({f"ends_at_human_cup_{m}": self.conflicts(m) for m in METHODS})
        out.update({f"final_goal_{m}": [r.final_goal for r in self.runs if r.method == m] for m in METHODS})
        out.update({f"reached_step_{m}": [r.reached_step for r in self.runs if r.method == m] for m in METHODS})
        # as the verdict reads it: from the step each leaves the human's cup for good (the settle steps' difference
        # said -14 where the verdict said +0)
        out["earlier_by"] = self.median_away("current") - self.median_away("prediction")
        out.update(protocol=self.config.protocol, library=self.library, scene=self.config.scene,
                   human_class=self.human.name,
                   human_class_distance_m=self.human.distance, w_human=self.config.w_human,
                   **settings_run(self.config.protocol, self.config.timing, self.config.volume, self.config.scene),
                   runs=[dataclasses.asdict(r) for r in self.runs])
        return out

    def lines(self) -> list[str]:
        """A table: per demonstration, each method's settle step, final goal and reach step."""
        out = [f"goal switch ({self.library}, scene {self.config.scene}, human: {self.human.name} -> "
               f"{self.config.human_cup}): the step from which the robot keeps its final goal",
               f"{'demo':>6}" + "".join(f"{m + ': settle / goal / reached':>40}" for m in METHODS)]
        by = {(r.demo, r.method): r for r in self.runs}
        for d in dict.fromkeys(r.demo for r in self.runs):
            cells = []
            for m in METHODS:
                r = by.get((d, m))
                cells.append("-" if r is None else f"{r.settle_step} / {r.final_goal} / "
                             f"{'not reached' if r.reached_step is None else r.reached_step}")
            out.append(f"{'#' + str(d):>6}" + "".join(f"{c:>40}" for c in cells))
        out.append("median settle step: " + ", ".join(f"{m} {self.median_settle(m):g}" for m in METHODS))
        out.append(f"median step from which the robot never again goes for {self.config.human_cup} (never = "
                   f"{self.config.timing.steps}): " + ", ".join(f"{m} {self.median_away(m):g}" for m in METHODS)
                   + "  (the paper: prediction 4, current 13)")
        n = len(self.settle("prediction"))
        out.append(f"runs ending at the human's cup ({self.config.human_cup}): "
                   + ", ".join(f"{m} {self.conflicts(m)} of {n}" for m in METHODS))
        return out


def run_switch(cfg: SwitchConfig, progress: Callable[[str], None] = print, compile: bool = True) -> SwitchResult:
    """Run the experiment (every run in lock-step through the four services)."""
    if not cfg.methods or any(m not in METHODS for m in cfg.methods):
        raise ValueError(f"switch: methods must be some of {', '.join(METHODS)}, got {cfg.methods}")
    prot = protocol(cfg.protocol)
    scene = load_scene(cfg.scene)
    cfg = dataclasses.replace(cfg, scene=scene.name)
    lib = load_experiment_library(cfg.library, scene)
    trial = authors_trial(cfg.trials, prot, scene.name, lib)
    human = human_class(lib, scene, trial, cfg.human_cup)
    cfg = dataclasses.replace(cfg, human_cup=human.cup)
    demos = lib.by_class(human.label)
    if trial is not None:  # the paper's library: the authors' class, its trial first
        demos = [demos[i] for i in trial[1] if i < len(demos)] + [d for i, d in enumerate(demos) if i not in trial[1]]
    demos = demos[: cfg.demos] if cfg.demos > 0 else demos
    cups = [c.name for c in scene.cups]
    progress(f"switch ({prot.name} protocol): {lib.source}, scene {scene.name}; robot -> {', '.join(cups)}; human -> "
             f"{cfg.human_cup}: class {human.name} (mean reach {human.distance:.3f} m from the cup); {len(demos)} "
             f"demonstrations, each held out in turn")
    models = HeldOutModels(lib, scene, Path(cfg.models_dir), cfg.components, cfg.volume or prot.volume)
    planner = build_planner(scene, cups, True, cfg.timing, compile=compile, w_human=cfg.w_human, protocol=prot)
    pacing = run_pacing(prot, scene.name, move3d_path_weights(planner.robot))
    result = SwitchResult(cfg, lib.source, human)
    total = len(demos) * len(cfg.methods)
    for i, demo in enumerate(demos):
        model = models.without([demo])
        path = human_file(lib, demo, Path(cfg.work_dir) / "humans")
        for j, method in enumerate(cfg.methods):
            spec = RunSpec(scene, model, path, samples_per_tick(demo, cfg.timing.steps), method=method,
                           steps=cfg.timing.steps, period_s=cfg.timing.period_s, seed=cfg.seed, **pacing)
            rec = run_lockstep(spec, planner)
            chosen = rec.chosen_goals()
            q, t = rec.q(), rec.stamps()
            contact = contact_summary(body_clearance(planner.robot, q, postures_at(rec.poses, t, scene)), t)
            res = rec.result
            run = SwitchRun(demo.index, method, tuple(chosen), tuple(rec.plans[0].goal_names) if rec.plans else (),
                            tuple(tuple(float(c) for c in p.cost_total) for p in rec.plans),
                            tuple(tuple(float(c) for c in p.cost_human) for p in rec.plans),
                            settle_step(chosen), away_step(chosen, cfg.human_cup), chosen[-1] if chosen else "",
                            final_reached(res, rec.plans[0].goal_names if rec.plans else [], chosen),
                            contact.min_clearance, contact.time_in_contact,
                            float(np.median([p.planning_ms for p in rec.plans])) if rec.plans else math.nan)
            result.runs.append(run)
            progress(f"  [{len(cfg.methods) * i + j + 1}/{total}] {run_line(run)}")
    return result


def run_line(run: SwitchRun) -> str:
    """One run's progress line; a run that ended short of its final goal says so, worded as interference does."""
    reached = f"reached step {run.reached_step}" if run.reached_step is not None else "not at its goal by the run's end"
    return (f"demo #{run.demo} {run.method:<10} goals {''.join(g[0] for g in run.goals)}  settle step "
            f"{run.settle_step}  final {run.final_goal}  {reached}")


def _colour(name: str) -> str:
    return {"red_cup": "tab:red", "blue_cup": "tab:blue"}.get(name, "tab:gray")


def plot_switch(result: SwitchResult, path: str | Path) -> Path:
    """Fig. 9: per-step cost of each candidate, current occupancy (top) and prediction (bottom).

    The product protocol plots each candidate's integral cost (the Plan's ``cost_total``); the paper protocol
    the cost its goal is chosen by (``cost_human``), with the authors' two traces (:data:`FIG9_TRACES`, their
    own units) in a column beside.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paper = result.config.protocol == "paper"
    fig, axes = plt.subplots(2, 2 if paper else 1, figsize=(12 if paper else 7, 6), sharex=True, squeeze=False)
    for row, method in enumerate(("current", "prediction")):
        ax = axes[row, 0]
        runs = [r for r in result.runs if r.method == method and r.cost_total]
        for r in runs:
            cost = np.array(r.cost_human if paper else r.cost_total)
            for k, name in enumerate(r.goal_names):
                ax.plot(np.arange(len(cost)), cost[:, k], color=_colour(name), alpha=0.15, lw=0.8)
        if runs:
            n = min(len(r.cost_total) for r in runs)
            stack = np.array([np.array(r.cost_human if paper else r.cost_total)[:n] for r in runs])  # (runs, steps, K)
            for k, name in enumerate(runs[0].goal_names):
                ax.plot(np.arange(n), np.median(stack[:, :, k], axis=0), color=_colour(name), lw=2.2,
                        label=f"{name} (median of {len(runs)})")
            # the verdict's measure (the paper's 4 against 13): the step it leaves the human's cup, not the settle
            away, steps = result.median_away(method), result.config.timing.steps
            if 0 < away < steps:
                ax.axvline(away, color="k", ls="--", lw=1, label=f"median step it leaves {result.config.human_cup}: "
                           f"{away:g}")
            elif not math.isnan(away):
                ax.plot([], [], " ", label=f"median run: {'never goes for' if away <= 0 else 'never leaves'} "
                        f"{result.config.human_cup}")
        ax.set_ylabel("prediction cost (goal choice)" if paper else "integral cost")
        ax.set_title(f"{'current occupancy only' if method == 'current' else 'predicted occupancy'}, Foresight "
                     f"({result.config.protocol} protocol)")
        ax.legend(fontsize=8)
        if paper:
            ax = axes[row, 1]
            for k, trace in FIG9_TRACES[method].items():
                ax.plot(np.arange(len(trace)), trace, color=("tab:gray", "k")[k], lw=2, label=f"authors' goal {k}")
            ax.set_ylabel("path cost, the authors' units")
            ax.set_title(f"{'current occupancy only' if method == 'current' else 'predicted occupancy'}, the authors' "
                         "run (gmm-gmr costs_motions.m)", fontsize=9)
            ax.legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("replanning step")
    cfg = result.config
    fig.suptitle(f"Fig. 9: {short_name(result.library)}, scene {cfg.scene}, human -> {cfg.human_cup}"
                 + ("; the authors' traces drawn in their own units (not rescaled)" if paper else ""), fontsize=10)
    from .plots import save_figure

    return save_figure(fig, path)
