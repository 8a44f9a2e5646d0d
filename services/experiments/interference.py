"""``foresight eval interference``: the paper's Table I, plus the human who was really there.

Protocol (section VI.B): the robot has one task (the red cup); the human performs a held-out
demonstration of the class that reaches for the other cup. Each run is 20 lock-step replanning steps
of 50 STOMP iterations, the human advanced by a fixed number of samples per step. Three planners
(:mod:`services.experiments.planners`): basic STOMP, least penetration of the predicted occupancy, and
the current occupancy only. 5 held-out demonstrations (one model trained without all five, as in the
paper) x 10 seeds.

Scored per run (:mod:`services.experiments.measures`): the integral penetration cost of the executed
trajectory against the final prediction of that demonstration (the paper's measure), and against the
real human: minimum clearance, time in contact and time within 5 cm.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shared.scene import load_scene

from .authors import table1_summary
from .harness import RunRecord, RunSpec, run_lockstep
from .heldout import (
    CupClass,
    HeldOutModels,
    draw_demos,
    human_class,
    human_file,
    load_experiment_library,
    samples_per_tick,
    table1_demos,
)
from .planners import VARIANTS, Timing, build_planner
from .protocol import (
    AUTHORS_TRIALS,
    TABLE1_SCENE,
    authors_trial,
    move3d_path_weights,
    protocol,
    run_pacing,
    settings_run,
)
from .reuse import first_differing_state, same_human, same_robot, with_human
from .scoring import RunScore, score_run

__all__ = ["TABLE1_SCENE", "InterferenceConfig", "InterferenceResult", "current_as_basic", "draw_demos", "ratio_text",
           "run_interference"]


PAPER_TABLE1 = {"basic": [24.41, 21.47, 27.52, 24.44, 25.13], "least_penetration": [0.41, 0.49, 0.60, 0.41, 0.74]}
"""The paper's Table I (mean over 10 runs per demonstration)."""


@dataclass(frozen=True)
class InterferenceConfig:
    """Options of the Table I experiment."""

    library: str = "synthetic"
    scene: str = TABLE1_SCENE
    robot_cup: str = "red_cup"
    human_cup: str = "blue_cup"
    demos: int = 5
    seeds: int = 10
    timing: Timing = Timing()
    components: int | None = None
    w_human: float | None = None  # None: the planner's default
    volume: str | None = None  # None: the trainer's default
    variants: tuple[str, ...] = tuple(VARIANTS)  # the planners run (``eval volumes``: least_penetration only)
    selection_seed: int = 0
    draw: int = 0  # the demonstrations are the first ``demos`` of the seed's draw of this many (0: of ``demos``):
    # the pace sweep's are Table I's first, so that its point at Table I's pace is Table I's on those
    protocol: str = "product"
    trials: str = "auto"  # authors: the authors' human motions; cup: the class nearest the human's cup; auto: the
    # authors' with the paper protocol on the paper's library, else cup
    path_per_step: float | None = None  # paper protocol: the robot's pace (None: the authors' for the scene)
    basic_once: bool = True  # basic STOMP planned once per seed, checked on the first (services.experiments.reuse)
    models_dir: Path = Path("models/experiments")
    work_dir: Path = Path("runs/experiments")


def ratio_text(ratio: float | None) -> str:
    """``12.3x``; ``inf`` where least penetration scores 0; ``n/a (0 / 0)`` where neither planner scores."""
    if ratio is None or math.isnan(ratio):
        return "n/a (0 / 0)"
    return "inf" if math.isinf(ratio) else f"{ratio:.1f}x"


@dataclass
class InterferenceResult:
    """All runs of the experiment and what they were."""

    config: InterferenceConfig
    library: str
    human: CupClass
    demos: list[int]
    runs: list[RunScore] = field(default_factory=list)
    current_as_basic: list[float] = field(default_factory=list)  # per run where current occupancy executed basic
    # STOMP's path (:func:`current_as_basic`): the largest human cost its planner gave a chosen path in that run
    trial: tuple[str, tuple[int, ...]] | None = None  # the authors' (class, motions) run (protocol.authors_trial)

    @property
    def borrowed(self) -> int:
        """Basic STOMP's scores made from another demonstration's run (:mod:`services.experiments.reuse`)."""
        return sum(r.borrowed for r in self.runs)

    def values(self, planner: str, measure: str) -> np.ndarray:
        """``(demos, seeds)`` values of one measure of one planner."""
        return np.array([[getattr(r, measure) for r in self.runs if r.planner == planner and r.demo == d]
                         for d in self.demos], dtype=np.float64)

    @property
    def names(self) -> list[str]:
        """The planners run, in :data:`~services.experiments.planners.VARIANTS` order."""
        return [n for n in VARIANTS if n in self.config.variants]

    def per_demo(self, planner: str, measure: str = "interference") -> tuple[list[float], list[float]]:
        """Mean and sample standard deviation over seeds, per demonstration (0 with one seed).

        The sample deviation (N - 1) is Matlab's ``std``, what the authors' costs_motions.m compares with.
        """
        v = self.values(planner, measure)
        return v.mean(axis=1).tolist(), (v.std(axis=1, ddof=1) if v.shape[1] > 1 else np.zeros(len(v))).tolist()

    def ratio(self) -> float:
        """Mean basic interference over mean least-penetration interference (the paper: 46)."""
        if not {"basic", "least_penetration"} <= set(self.names):
            return math.nan
        lp = self.values("least_penetration", "interference").mean()
        basic = self.values("basic", "interference").mean()
        if lp > 0:
            return float(basic / lp)
        return math.inf if basic > 0 else math.nan  # 0 / 0: neither entered the final prediction

    def contact_violations(self) -> int:
        """Runs (demo, seed) where least penetration spent longer in contact than basic STOMP."""
        if not {"basic", "least_penetration"} <= set(self.names):
            return 0
        return int(np.sum(self.values("least_penetration", "time_in_contact")
                          > self.values("basic", "time_in_contact") + 1e-9))

    def to_json(self) -> dict[str, Any]:
        """``basic``, ``least_penetration``, ``current``: per-demonstration mean interference; and more."""
        out: dict[str, Any] = {name: self.per_demo(name)[0] for name in self.names}
        out.update({f"{name}_std": self.per_demo(name)[1] for name in self.names})
        for measure in ("min_clearance", "time_in_contact", "time_near"):
            out[measure] = {name: self.per_demo(name, measure)[0] for name in self.names}
        out["median_min_clearance"] = {n: float(np.median(self.values(n, "min_clearance"))) for n in self.names}
        for part in ("interference_at_goal", "interference_unrecognised"):
            out[part] = {name: self.per_demo(name, part)[0] for name in self.names}
        out["ratio_basic_over_least_penetration"] = self.ratio()
        out["runs_with_more_contact_than_basic"] = self.contact_violations()
        out["current_runs_as_basic"] = len(self.current_as_basic)
        out["authors_comparison"] = self.authors_comparison()
        out["reached"] = {n: int(sum(r.reached_step is not None for r in self.runs if r.planner == n))
                          for n in self.names}
        out.update(protocol=self.config.protocol, library=self.library, scene=self.config.scene,
                   human_class=self.human.name,
                   human_class_distance_m=self.human.distance, demos=self.demos, seeds=self.config.seeds,
                   robot_cup=self.config.robot_cup, human_cup=self.human.cup,
                   w_human=self.config.w_human, basic_runs_borrowed=self.borrowed,
                   **settings_run(self.config.protocol, self.config.timing, self.config.volume, self.config.scene,
                                  self.config.path_per_step),
                   runs=[dataclasses.asdict(r) for r in self.runs])
        return out

    def unit(self, short: bool = False) -> str:
        """What the interference is measured in: per second (``product`` protocol) or along the path (``paper``)."""
        if self.config.protocol == "product":
            return "p-voxel s" if short else "probability-voxels x s"
        return "p-voxel x C-space length" if short else "probability-voxels x configuration-space length"

    def lines(self) -> list[str]:
        """The Table I layout: one row per demonstration, mean (std) over seeds; then the real human."""
        names = self.names
        head = f"{'demo':>6}" + "".join(f"{VARIANTS[n].label:>22}" for n in names)
        unit = self.unit()
        seeds = f"{self.config.seeds} seed{'s' * (self.config.seeds != 1)}"
        out = [f"interference with the final prediction ({unit}), {self.config.protocol} protocol, mean (std) of "
               f"{seeds}; {self.library}, scene {self.config.scene}, human: {self.human.name}", head]
        stats = {n: self.per_demo(n) for n in names}
        spread = (lambda x: f"({x:5.3f})") if self.config.seeds > 1 else (lambda x: "(  n/a)")  # one seed: no std
        for i, d in enumerate(self.demos):
            cells = "".join(f"{stats[n][0][i]:>14.3f} {spread(stats[n][1][i])}" for n in names)
            out.append(f"{'#' + str(d):>6}" + cells)
        out.append(f"{'mean':>6}" + "".join(f"{np.mean(stats[n][0]):>22.3f}" for n in names))
        paper = np.mean(PAPER_TABLE1["basic"]) / np.mean(PAPER_TABLE1["least_penetration"])
        out.append(f"basic / least penetration: {ratio_text(self.ratio())} (the paper: {paper:.0f}x)")
        for part, what in (("interference_at_goal", "once at the goal"),
                           ("interference_unrecognised", "before the human's class was recognised (p < 0.5)")):
            mean = {n: float(self.values(n, part).mean()) for n in names}
            out.append(f"of which accrued {what}: " + ", ".join(f"{VARIANTS[n].label} {mean[n]:.3f}" for n in names))
        out.append("")
        out.append("the real human: min clearance (m) / time in contact (s) / time within 5 cm (s), mean of seeds")
        out.append(f"{'demo':>6}" + "".join(f"{VARIANTS[n].label:>26}" for n in names))
        for i, d in enumerate(self.demos):
            cells = []
            for n in names:
                c, k, w = (self.per_demo(n, m)[0][i] for m in ("min_clearance", "time_in_contact", "time_near"))
                cells.append(f"{c:>+10.3f} / {k:5.2f} / {w:5.2f}")
            out.append(f"{'#' + str(d):>6}" + "".join(f"{s:>26}" for s in cells))
        med = {n: float(np.median(self.values(n, "min_clearance"))) for n in names}
        out.append("median min clearance: " + ", ".join(f"{VARIANTS[n].label} {med[n]:+.3f} m" for n in names))
        out.append(f"runs where least penetration touched the human longer than basic STOMP: "
                   f"{self.contact_violations()} of {len(self.demos) * self.config.seeds}")
        reached = self.to_json()["reached"]
        out.append("runs that reached the goal by their end: " + ", ".join(f"{VARIANTS[n].label} {reached[n]}"
                                                                            for n in names))
        if self.current_as_basic:  # Table I's two equal columns, said why (docs/experiments.md)
            top = max(self.current_as_basic)
            cost = ("0 at every step: the human's present posture never lay on the path it chose" if top == 0
                    else f"at most {top:.4f}")
            n = len(self.current_as_basic)
            out.append(f"current occupancy executed basic STOMP's path, state for state, in {n} of "
                       f"{len(self.demos) * self.config.seeds} runs (its chosen paths' human cost: {cost})")
        if self.borrowed:
            out.append(f"basic STOMP ignores the human: its path was the same on every demonstration at seed 0 "
                       f"(compared to the bit), so at the other seeds it was planned on #{self.demos[0]} and scored "
                       f"against each demonstration ({self.borrowed} of {len(self.demos) * self.config.seeds} runs)")
        return out + self.authors_lines()

    def authors_trials(self) -> bool:
        """Whether these runs are the authors' Table I trials (paper protocol, their motions 25-29).

        As :func:`~services.experiments.protocol.authors_trial` recognised them, by the library's values: by the class's
        name, a generated library's compound_1 was compared with the authors' costs.
        """
        trial = self.trial
        return (self.config.protocol == "paper" and trial is not None and self.human.name == trial[0]
                and tuple(self.demos[:len(trial[1])]) == trial[1][:len(self.demos)])

    def authors_comparison(self) -> list[dict[str, Any]]:
        """Per motion and planner: the authors' 10 runs (mean, min, max) and these runs (mean, min, max).

        Their motions only: the class's other demonstrations (``--demos`` above 5) have no run of theirs.
        """
        if not self.authors_trials() or not {"basic", "least_penetration"} <= set(self.names):
            return []
        theirs_of = len(AUTHORS_TRIALS[self.config.scene][1])
        rows = []
        for name in ("basic", "least_penetration"):
            theirs = table1_summary(name)
            ours = self.values(name, "interference")
            for i, d in enumerate(self.demos[:theirs_of]):
                rows.append({"planner": name, "motion": 25 + d, "demo": d, "authors": theirs[d],
                             "ours": {"mean": float(ours[i].mean()),
                                      "std": float(ours[i].std(ddof=1)) if ours.shape[1] > 1 else math.nan,  # as theirs
                                      "min": float(ours[i].min()), "max": float(ours[i].max())}})
        return rows

    def authors_lines(self) -> list[str]:
        """The comparison with the authors' runs (costs_motions.m), when these are their trials."""
        rows = self.authors_comparison()
        if not rows:
            return []
        out = ["", "beside the authors' runs (gmm-gmr costs_motions.m, 10 runs each; their units: the cost summed over "
               "mesh-triangle centroids, ours over distinct voxels of the collision spheres' surfaces)",
               f"{'motion':>7}{'planner':>20}{'authors mean [min, max]':>30}{'paper protocol mean [min, max]':>34}"]
        for r in rows:
            a, o = r["authors"], r["ours"]
            out.append(f"{r['motion']:>7}{VARIANTS[r['planner']].label:>20}"
                       f"{a['mean']:>12.3f} [{a['min']:.3f}, {a['max']:.3f}]{o['mean']:>14.3f} "
                       f"[{o['min']:.3f}, {o['max']:.3f}]")
        theirs = {n: np.mean([r["authors"]["mean"] for r in rows if r["planner"] == n])
                  for n in ("basic", "least_penetration")}
        ours = {n: float(np.mean([r["ours"]["mean"] for r in rows if r["planner"] == n]))
                for n in ("basic", "least_penetration")}  # on their motions, as theirs
        lp = ours["least_penetration"]
        ratio = ours["basic"] / lp if lp > 0 else (math.inf if ours["basic"] > 0 else math.nan)
        out.append(f"basic / least penetration: the authors' runs "
                   f"{theirs['basic'] / theirs['least_penetration']:.1f}x, the paper protocol here "
                   f"{ratio_text(ratio)}")
        return out


def run_interference(cfg: InterferenceConfig, progress: Callable[[str], None] = print,
                     compile: bool = True) -> InterferenceResult:
    """Run the experiment (every run in lock-step through the four services)."""
    unknown = [v for v in cfg.variants if v not in VARIANTS]
    if unknown or not cfg.variants:
        raise ValueError(f"interference: variants must be some of {', '.join(VARIANTS)}, got {cfg.variants}")
    variants = {name: v for name, v in VARIANTS.items() if name in cfg.variants}
    prot = protocol(cfg.protocol)
    scene = load_scene(cfg.scene)
    cfg = dataclasses.replace(cfg, scene=scene.name)  # the result names its scene (PR2TwoCupsSide -> its file name)
    lib = load_experiment_library(cfg.library, scene)
    trial = authors_trial(cfg.trials, prot, scene.name, lib)
    human = human_class(lib, scene, trial, cfg.human_cup)
    pool = lib.by_class(human.label)
    picked, how = table1_demos(len(pool), human.held_out(len(pool), cfg.demos), trial, cfg.selection_seed, cfg.draw)
    demos = [pool[i] for i in picked]
    progress(f"interference ({prot.name} protocol): {lib.source}, scene {scene.name}; robot -> {cfg.robot_cup}; "
             f"human -> {human.cup}: class {human.name} (mean reach {human.distance:.3f} m from the cup), "
             f"demonstrations {[d.index for d in demos]} ({how}, held out)")
    if human.warning():
        progress(human.warning())
    volume = cfg.volume or prot.volume
    model = HeldOutModels(lib, scene, Path(cfg.models_dir), cfg.components, volume).without(demos)
    planners = {flag: build_planner(scene, [cfg.robot_cup], flag, cfg.timing, compile=compile, w_human=cfg.w_human,
                                    protocol=prot)
                for flag in sorted({v.human_cost for v in variants.values()})}
    weights = move3d_path_weights(next(iter(planners.values())).robot) if prot.measure == "path" else None
    pacing = run_pacing(prot, scene.name, weights)
    if cfg.path_per_step is not None and pacing["path_per_step"]:
        pacing["path_per_step"] = cfg.path_per_step
    result = InterferenceResult(cfg, lib.source, human, [d.index for d in demos], trial=trial)
    total, done = len(demos) * cfg.seeds * len(variants), 0
    paths = {demo.index: human_file(lib, demo, Path(cfg.work_dir) / "humans") for demo in demos}
    finals: dict[int, Any] = {}
    # basic STOMP once per seed (services.experiments.reuse): checked on the first seed, then borrowed
    once = cfg.basic_once and "basic" in variants and "least_penetration" in variants and len(demos) > 1
    basic_of_seed: dict[int, RunRecord] = {}
    for seed in range(cfg.seeds):  # seed by seed: the first seed's check comes before any borrowing
        for demo in demos:
            recs: dict[str, RunRecord] = {}
            scores: dict[str, RunScore] = {}
            borrow = once and seed > 0 and demo is not demos[0]
            order = [n for n in variants if n != "basic"] + ["basic"] if borrow else list(variants)
            for name in order:  # basic first: a prediction run gives the final grid
                variant = variants[name]
                planner = planners[variant.human_cost]
                if borrow and name == "basic":
                    rec = with_human(basic_of_seed[seed], recs["least_penetration"])
                else:
                    spec = RunSpec(scene, model, paths[demo.index], samples_per_tick(demo, cfg.timing.steps),
                                   method=variant.method, steps=cfg.timing.steps, period_s=cfg.timing.period_s,
                                   seed=seed, **pacing)
                    rec = run_lockstep(spec, planner)
                recs[name] = rec
                if demo.index not in finals and variant.method == "prediction" and rec.final_occupancy is not None:
                    finals[demo.index] = rec.final_occupancy
                if demo.index not in finals:
                    raise RuntimeError("interference: no final prediction was received")
                borrowed = borrow and name == "basic"
                scores[name] = dataclasses.replace(score_run(rec, planner.robot, scene, finals[demo.index], demo.index,
                                                             seed, name, human.label, weights), borrowed=borrowed)
                done += 1
                how = f"  (demo #{demos[0].index}'s path: basic STOMP ignores the human)" if borrowed else ""
                step = scores[name].reached_step
                reached = f"reached step {step}" if step is not None else "not at its goal by the run's end"
                progress(f"  [{done}/{total}] demo #{demo.index} seed {seed} {variant.label:<18} interference "
                         f"{scores[name].interference:8.3f}  min clearance {scores[name].min_clearance:+.3f} m  "
                         f"{reached}{how}")
            result.runs.extend(scores[name] for name in variants)
            if (cost := current_as_basic(recs)) is not None:
                result.current_as_basic.append(cost)
            if once and "basic" in recs and not borrow:
                basic_of_seed.setdefault(seed, recs["basic"])
                once = _basic_is_shared(recs, basic_of_seed[seed], demo.index, progress) if seed == 0 else once
    return result


def current_as_basic(recs: dict[str, RunRecord]) -> float | None:
    """Where current occupancy executed basic STOMP's path, the largest human cost its planner gave a chosen path.

    Its planner costs the human's present posture only; where that posture never lies on the paths it weighs,
    it plans what basic STOMP plans, and Table I's two columns are equal. None: either did not run, or their
    executed configurations differ (:func:`~services.experiments.reuse.first_differing_state`).
    """
    if "current" not in recs or "basic" not in recs:
        return None
    if first_differing_state(recs["current"], recs["basic"]) is not None:
        return None
    return max((float(p.cost_human[p.chosen]) for p in recs["current"].plans), default=0.0)


def _basic_is_shared(recs: dict[str, RunRecord], first: RunRecord, demo: int, progress: Callable[[str], None]) -> bool:
    """The first seed's check that basic STOMP's run can be borrowed (:mod:`services.experiments.reuse`)."""
    if recs["basic"] is not first and not same_robot(recs["basic"], first):  # the first demonstration is first
        at = first_differing_state(recs["basic"], first)
        progress(f"  basic STOMP's path on demo #{demo} differs from the first demonstration's"
                 f"{'' if at is None else f' from t = {at:.3f} s'}: every run is made")
        return False
    if not same_human(recs["basic"], recs["least_penetration"]):
        progress(f"  basic STOMP's and least penetration's runs of demo #{demo} saw different human streams: "
                 "every run is made")
        return False
    return True
