"""``foresight eval all --out DIR``: every experiment and the timings, one Markdown report with its PNGs.

For each library (default: the synthetic one and, when it is beside the repository, the paper's):
recognition (Fig. 6), interference (Table I), goal switch (Fig. 8-9), then the timings (planning ms per
step from every run, prediction ms per pose). Each section sets the measured numbers beside the
paper's and says by how much they differ; docs/experiments.md explains the differences.

``--quick`` (about 2 minutes on 2 cores, run in CI): the synthetic library only, 4 Gaussians per
class, recognition on 4 demonstrations per class, Table I with 1 demonstration x 2 seeds, the switch
with 2 demonstrations, 20 STOMP iterations per step, the cost evaluated eagerly (no compile).
The full report (the paper's protocol: 20 Gaussians, 5 demonstrations x 10 seeds, every
demonstration of the class, 50 iterations) takes about 10 minutes on 2 quiet cores
(docs/experiments.md, "Run time"). ``--volume`` picks the held-out models' occupancy volume.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from services.predictor.volumes import DEFAULT_VOLUME, VOLUMES
from shared.library import MotionLibrary
from shared.native_threads import limit_blas_threads
from shared.scene import load_scene

from .heldout import SYNTHETIC, load_experiment_library
from .interference import PAPER_TABLE1, TABLE1_SCENE, InterferenceConfig, InterferenceResult, run_interference
from .planners import Timing
from .plots import plot_interference
from .switch import SwitchConfig, SwitchResult, plot_switch, run_switch

__all__ = ["ReportPlan", "QUICK", "FULL", "add_report_arguments", "library_section", "run_report", "PAPER_LIBRARY"]

PAPER_LIBRARY = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "paper-library"
"""Where the paper's library lies beside a checkout (``../shared/data/paper-library``)."""


@dataclass(frozen=True)
class ReportPlan:
    """How much of each experiment a report runs."""

    components: int
    recognition_demos: int  # per class, 0: all
    table1_demos: int
    table1_seeds: int
    switch_demos: int  # 0: all of the class
    iterations: int
    compile: bool


FULL = ReportPlan(components=20, recognition_demos=0, table1_demos=5, table1_seeds=10, switch_demos=0,
                  iterations=50, compile=True)
QUICK = ReportPlan(components=4, recognition_demos=4, table1_demos=1, table1_seeds=2, switch_demos=2,
                   iterations=20, compile=False)


def add_report_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``foresight eval all``."""
    p.add_argument("--out", type=Path, default=Path("runs/report"), help="report directory (default: runs/report)")
    p.add_argument("--quick", action="store_true", help="the small variant (about 2 minutes; see above)")
    p.add_argument("--libraries", default="", help="comma-separated libraries ('synthetic' or paths); default: "
                   "synthetic and the paper's library when it is at ../shared/data/paper-library (--quick: "
                   "synthetic only)")
    p.add_argument("--models-dir", type=Path, default=Path("models/experiments"), help="held-out models cache")
    p.add_argument("--volume", choices=VOLUMES, default=DEFAULT_VOLUME, help="occupancy volume of the held-out "
                   f"prediction models (foresight train --volume; default: {DEFAULT_VOLUME}; the paper's: paper)")


def _subset(lib: MotionLibrary, per_class: int) -> MotionLibrary:
    if per_class <= 0:
        return lib
    demos = [d for m in range(lib.n_classes) for d in lib.by_class(m)[:per_class]]
    return MotionLibrary(list(lib.class_names), demos, [], f"{lib.source} (first {per_class} per class)")


def _recognition(lib: MotionLibrary, plan: ReportPlan, out: Path, tag: str, n_jobs: int
                 ) -> tuple[list[str], dict[str, Any]]:
    from services.predictor.gmm import GMMConfig
    from services.predictor.recognition import PAPER_FIG6, leave_one_out, plot_recognition

    sub = _subset(lib, plan.recognition_demos)
    res = leave_one_out(sub, GMMConfig(n_components=plan.components), n_jobs=n_jobs, progress=False)
    png = plot_recognition([res], out / f"recognition-{tag}.png", f"leave-one-out recognition: {sub.source}")
    rates = dict(zip(res.fractions, res.rates, strict=True))
    lines = ["| executed | " + " | ".join(f"{f:.0%}" for f in res.fractions) + " |",
             "|---|" + "---|" * len(res.fractions),
             "| recognised | " + " | ".join(f"{r:.1%}" for r in res.rates) + " |", ""]
    for f, target in zip(PAPER_FIG6["fractions"], PAPER_FIG6["rates"], strict=True):
        near = min(rates, key=lambda x, f=f: abs(x - f))
        lines.append(f"- paper: {target:.0%} at {f:.0%} executed; measured {rates[near]:.1%} at {near:.0%} "
                     f"({100 * (rates[near] - target):+.1f} points)")
    lines += ["", f"![recognition]({png.name})", ""]
    return lines, {"fractions": res.fractions, "rates": res.rates, "plot": png.name}


def _table1_section(res: InterferenceResult, png: Path) -> list[str]:
    lines = ["```", *res.lines(), "```", ""]
    basic = float(np.mean(res.per_demo("basic")[0]))
    lp = float(np.mean(res.per_demo("least_penetration")[0]))
    cur = float(np.mean(res.per_demo("current")[0]))
    paper_b, paper_lp = np.mean(PAPER_TABLE1["basic"]), np.mean(PAPER_TABLE1["least_penetration"])
    lines.append(f"- paper: basic {paper_b:.2f}, least penetration {paper_lp:.2f}: {paper_b / paper_lp:.0f}x. "
                 f"Measured: basic {basic:.3f}, least penetration {lp:.3f}, current {cur:.3f}: "
                 f"{res.ratio():.1f}x (target >= 20x; least penetration below current: {lp < cur}).")
    lines.append("- The absolute values are not comparable with the paper's: its robot points and voxels are "
                 "its own (Move3D's PR2 surface samples); the ratio is.")
    early = float(np.mean(res.per_demo("least_penetration", "interference_unrecognised")[0]))
    if lp > 0:
        lines.append(f"- {100 * early / lp:.0f}% of least penetration's interference was accrued in steps planned "
                     "before the human's class was recognised (p < 0.5): the robot crosses the human's path while "
                     "the prediction is still spread over the classes (docs/experiments.md).")
    if basic == 0:
        lines.append("- Basic STOMP never enters the final prediction here: the task does not cross the "
                     "predicted human volume, so there is nothing for the prediction to remove.")
    lines += ["", f"![interference]({png.name})", ""]
    return lines


def _switch_section(res: SwitchResult, png: Path) -> list[str]:
    lines = ["```", *res.lines(), "```", ""]
    p, c = res.median_settle("prediction"), res.median_settle("current")
    lines.append(f"- paper: prediction settles at step 4, current at step 13 (9 steps earlier). Measured medians: "
                 f"prediction {p:g}, current {c:g} ({c - p:+g} steps; target >= 5 earlier).")
    ap, ac = res.median_away("prediction"), res.median_away("current")
    lines.append(f"- step from which the robot never again goes for the human's cup ({res.config.human_cup}; a run "
                 f"that ends there counts {res.config.timing.steps}): prediction {ap:g}, current {ac:g} "
                 f"({ac - ap:+g}); runs ending at the human's cup: prediction {res.conflicts('prediction')}, "
                 f"current {res.conflicts('current')}.")
    for method in ("prediction", "current"):
        held = _held_costs(res, method)
        if held:
            human, total, other = (np.array(x) for x in zip(*held, strict=True))
            lines.append(f"- {method}: while the robot holds at the human's cup ({len(held)} steps), that "
                         f"candidate's human cost is {human.max():.4f} at most (the goal's predicted occupancy for "
                         f"the time the robot stays there, `goal_dwell_s`); holding cost {np.median(total):.4f} "
                         f"(median) against {np.median(other):.4f} for the other cup's trajectory (Algorithm 1 "
                         "keeps the least).")
    goals = {m: [r.final_goal for r in res.runs if r.method == m] for m in ("prediction", "current")}
    for m, g in goals.items():
        counts = {name: g.count(name) for name in sorted(set(g))}
        lines.append(f"- final goal with {m}: " + ", ".join(f"{k} in {v} runs" for k, v in counts.items()))
    lines += ["", f"![switch]({png.name})", ""]
    return lines


def _held_costs(res: SwitchResult, method: str) -> list[tuple[float, float, float]]:
    """The costs while ``method``'s robot holds the human's cup (reached, chosen, and its final goal).

    Returns:
        Per such step: that candidate's human and total cost, and the least total cost of the others.
    """
    cup, out = res.config.human_cup, []
    for r in res.runs:
        if r.method != method or r.final_goal != cup or r.reached_step is None:
            continue
        h = r.goal_names.index(cup)
        for s in range(r.reached_step + 1, min(len(r.cost_total), len(r.goals))):
            if r.goals[s] == cup:
                others = [c for i, c in enumerate(r.cost_total[s]) if i != h]
                out.append((r.cost_human[s][h], r.cost_total[s][h], min(others, default=math.inf)))
    return out


def _prediction_ms(lib: MotionLibrary, models_dir: Path, components: int, volume: str) -> dict[str, float]:
    """Median and p90 ms of one predictor update (pose -> occupancy), over one demonstration per class."""
    from services.predictor.core import PredictorCore
    from services.predictor.model import PredictionModel

    from .heldout import HeldOutModels

    scene = load_scene(TABLE1_SCENE)
    model = PredictionModel.load(HeldOutModels(lib, scene, models_dir, components, volume).without([]))
    core = PredictorCore(model, scene)
    times = []
    for m in range(lib.n_classes):
        demo = lib.by_class(m)[0]
        core.reset(m)
        for f in demo.features:
            t0 = time.perf_counter()
            core.update(f)
            times.append((time.perf_counter() - t0) * 1e3)
    return {"median_ms": float(np.median(times)), "p90_ms": float(np.percentile(times, 90)), "poses": len(times)}


def library_section(spec: str, plan: ReportPlan, out: Path, models_dir: Path, n_jobs: int = 2,
                    volume: str = DEFAULT_VOLUME) -> tuple[list[str], dict[str, Any]]:
    """Every experiment on one library: its Markdown section and its data (``planning_ms`` K=1 and K=2 runs)."""
    tag = SYNTHETIC if spec == SYNTHETIC else Path(spec).name

    def say(line: str) -> None:
        print(f"[{tag}] {line}", flush=True)

    timing = Timing(iterations=plan.iterations)
    lib = load_experiment_library(spec, load_scene(TABLE1_SCENE))
    say(f"recognition, leave-one-out on {lib.source}")
    md = [f"## Library: {lib.source}", "", "### Recognition (Fig. 6)", ""]
    lines, rec = _recognition(lib, plan, out, tag, n_jobs)
    md += lines
    common = {"library": spec, "timing": timing, "components": plan.components, "models_dir": models_dir,
              "work_dir": out / "work", "volume": volume}
    t1 = run_interference(InterferenceConfig(demos=plan.table1_demos, seeds=plan.table1_seeds, **common), say,
                          compile=plan.compile)
    png1 = plot_interference(t1, out / f"interference-{tag}.png")
    md += ["### Interference (Table I)", "", *_table1_section(t1, png1)]
    sw = run_switch(SwitchConfig(demos=plan.switch_demos, **common), say, compile=plan.compile)
    png2 = plot_switch(sw, out / f"switch-{tag}.png")
    md += ["### Goal switch (Fig. 8-9)", "", *_switch_section(sw, png2)]
    first = {r.goals[0] for r in sw.runs if r.goals}
    mirrored = None
    if len(first) == 1 and sw.config.human_cup not in first:
        # the paper's situation: the human reaches for the cup the robot goes for first, so it must switch
        cup = first.pop()
        say(f"the robot first goes for {cup}, not {sw.config.human_cup}: the switch again with the human reaching "
            f"for {cup}")
        mirrored = run_switch(SwitchConfig(demos=plan.switch_demos, human_cup=cup, **common), say,
                              compile=plan.compile)
        png3 = plot_switch(mirrored, out / f"switch-mirrored-{tag}.png")
        md += [f"### Goal switch, the human reaching for {cup} (the robot's first choice)", "",
               f"With an empty grid the robot first goes for {cup}, so with the human reaching for "
               f"{sw.config.human_cup} neither planner has a reason to switch. The paper's Fig. 8-9 has the human "
               "reach for the cup the robot first goes for; this run does the same here.", "",
               *_switch_section(mirrored, png3)]
    data = {"recognition": rec, "interference": t1.to_json(), "switch": sw.to_json(),
            "switch_mirrored": mirrored.to_json() if mirrored is not None else None,
            "prediction_ms": _prediction_ms(lib, models_dir, plan.components, volume),
            "planning_ms": {"K=1": [r.planning_ms for r in t1.runs],
                            "K=2": [r.planning_ms for r in sw.runs + (mirrored.runs if mirrored else [])]}}
    return md, data


def run_report(args: argparse.Namespace) -> int:
    """Run every experiment and write ``report.md`` and its PNGs to ``args.out``; returns 0.

    Two libraries run in two worker processes at once (one per core); one library runs in this process.
    """
    plan = QUICK if args.quick else FULL
    libs = [s.strip() for s in args.libraries.split(",") if s.strip()]
    if not libs:
        libs = [SYNTHETIC] + ([] if args.quick or not PAPER_LIBRARY.is_dir() else [str(PAPER_LIBRARY)])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    timing = Timing(iterations=plan.iterations)
    started = time.monotonic()
    workers = min(len(libs), max(1, (os.cpu_count() or 1)))
    if workers > 1:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=limit_blas_threads) as pool:
            futures = [pool.submit(library_section, spec, plan, out, Path(args.models_dir), 1, args.volume)
                       for spec in libs]
            sections = [f.result() for f in futures]
    else:
        sections = [library_section(spec, plan, out, Path(args.models_dir), volume=args.volume) for spec in libs]
    md = [f"# Foresight: the paper's experiments ({'quick' if args.quick else 'full'} run)", "",
          f"Command: `foresight eval all --out {out}{' --quick' if args.quick else ''}"
          f"{'' if args.volume == DEFAULT_VOLUME else ' --volume ' + args.volume}`. Timing of every run: "
          f"{timing.steps} steps of {timing.period_s} s, {timing.iterations} STOMP iterations, robot at "
          f"{timing.robot_speed:g} of its velocity limits; {plan.components} Gaussians per class; occupancy "
          f"volume `{args.volume}` (`foresight train --volume`; the paper's is `paper`). Why the numbers differ "
          "from the paper's: docs/experiments.md.", ""]
    data: dict[str, Any] = {"plan": plan.__dict__, "volume": args.volume, "libraries": {}}
    planning: dict[str, list[float]] = {"K=1": [], "K=2": []}
    for spec, (lines, d) in zip(libs, sections, strict=True):
        md += lines
        data["libraries"][SYNTHETIC if spec == SYNTHETIC else Path(spec).name] = d
        for k in planning:
            planning[k] += d["planning_ms"][k]
    how = "side by side, one process per core" if workers > 1 else "in one process"
    md += ["## Timing", "", f"{len(libs)} libraries ran {how}.", "",
           "| measure | median | p90 | samples |", "|---|---|---|---|"]
    for k, v in planning.items():
        if v:
            md.append(f"| planning ms per step, {k} (median of each run) | {np.median(v):.1f} | "
                      f"{np.percentile(v, 90):.1f} | {len(v)} runs |")
    for tag, d in data["libraries"].items():
        p = d["prediction_ms"]
        md.append(f"| prediction ms per pose ({tag}) | {p['median_ms']:.2f} | {p['p90_ms']:.2f} | {p['poses']} poses |")
    md += ["", "The paper: about 500 ms per replanning step for one goal (50 iterations).",
           "", f"Report made in {time.monotonic() - started:.0f} s.", ""]
    (out / "report.md").write_text("\n".join(md))
    (out / "report.json").write_text(json.dumps(data, default=_json_default))
    print(f"eval all: wrote {out / 'report.md'} and its PNGs in {time.monotonic() - started:.0f} s", flush=True)
    return 0


def _json_default(o: Any) -> Any:
    if isinstance(o, Path):
        return str(o)
    if isinstance(o, float) and math.isnan(o):
        return None
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
