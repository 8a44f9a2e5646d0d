"""The report's section of one library: recognition, each protocol's Table I and switch, the pace sweep.

:func:`library_part` makes one independent part (``recognition``, or a protocol's Table I, switch or pace sweep:
:func:`part_names`) and :func:`library_section`
assembles a library's parts into its Markdown section and its data; :func:`services.experiments.report.run_report`
runs the parts of every library in parallel, in worker processes (``report.report_workers``: one per core plus one).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from services.predictor.volumes import DEFAULT_VOLUME
from shared.library import MotionLibrary
from shared.scene import load_scene

from .fit_store import fit_store
from .heldout import library_tag, load_experiment_library
from .interference import (
    PAPER_TABLE1,
    TABLE1_SCENE,
    InterferenceConfig,
    InterferenceResult,
    ratio_text,
    run_interference,
)
from .pace import DEFAULT_PACES, PaceConfig, PacePoint, PaceResult, run_pace
from .planners import Timing
from .plots import plot_interference
from .protocol import PROTOCOLS, protocol
from .switch import SwitchConfig, SwitchResult, plot_switch, run_switch
from .verdicts import switch_verdict, table1_verdict

if TYPE_CHECKING:
    from .report import ReportPlan

__all__ = ["PROTOCOL_PARTS", "part_names", "part_weight", "library_part", "library_section", "PROTOCOL_TEXT"]


def _subset(lib: MotionLibrary, per_class: int) -> MotionLibrary:
    if per_class <= 0:
        return lib
    demos = [d for m in range(lib.n_classes) for d in lib.by_class(m)[:per_class]]
    return MotionLibrary(list(lib.class_names), demos, [], f"{lib.source} (first {per_class} per class)")


def _recognition(lib: MotionLibrary, plan: ReportPlan, out: Path, tag: str, n_jobs: int, models_dir: Path
                 ) -> tuple[list[str], dict[str, Any]]:
    from services.predictor.gmm import GMMConfig
    from services.predictor.recognition import PAPER_FIG6, leave_one_out, plot_recognition

    sub = _subset(lib, plan.recognition_demos)
    # in one process, the refits are the held-out models' class fits: one entry of the models' store for both
    fits = fit_store(Path(models_dir) / "fits") if n_jobs == 1 else None
    res = leave_one_out(sub, GMMConfig(n_components=plan.components), n_jobs=n_jobs, progress=False, fit_cache=fits)
    png = plot_recognition([res], out / f"recognition-{tag}.png", f"leave-one-out recognition: {sub.source}")
    lines = ["| executed | " + " | ".join(f"{f:.0%}" for f in res.fractions) + " |",
             "|---|" + "---|" * len(res.fractions),
             "| recognised | " + " | ".join(f"{r:.1%}" for r in res.rates) + " |", ""]
    for f, target in zip(PAPER_FIG6["fractions"], PAPER_FIG6["rates"], strict=True):
        lines.append(f"- paper: {target:.0%} at {f:.0%} executed; measured {_rate_at(res, f):.1%} there"
                     f"{_between(res.fractions, f)} ({100 * (_rate_at(res, f) - target):+.1f} points)")
    lines += ["", f"![recognition]({png.name})", ""]
    return lines, {"fractions": res.fractions, "rates": res.rates, "plot": png.name}


def _rate_at(res: Any, fraction: float) -> float:
    """The recognition rate at ``fraction`` executed, interpolated between the measured fractions.

    The paper's 50 % at 43 % was compared with the rate at the nearest grid point, 40 %.
    """
    order = np.argsort(res.fractions)
    return float(np.interp(fraction, np.asarray(res.fractions)[order], np.asarray(res.rates)[order]))


def _between(fractions: Sequence[float], f: float) -> str:
    """`` (interpolated, 40-50 %)`` where ``f`` is not a measured fraction, else ""."""
    if any(abs(x - f) < 1e-9 for x in fractions):
        return ""
    lo, hi = max((x for x in fractions if x < f), default=None), min((x for x in fractions if x > f), default=None)
    return f" (interpolated, {lo:.0%}-{hi:.0%})" if lo is not None and hi is not None else " (the nearest measured)"


def _table1_section(res: InterferenceResult, png: Path) -> list[str]:
    lines = ["```", *res.lines(), "```", ""]
    basic = float(np.mean(res.per_demo("basic")[0]))
    lp = float(np.mean(res.per_demo("least_penetration")[0]))
    cur = float(np.mean(res.per_demo("current")[0]))
    paper_b, paper_lp = np.mean(PAPER_TABLE1["basic"]), np.mean(PAPER_TABLE1["least_penetration"])
    lines.append(f"- verdict ({res.config.protocol} protocol): {table1_verdict(res)}.")
    lines.append(f"- paper: basic {paper_b:.2f}, least penetration {paper_lp:.2f}: {paper_b / paper_lp:.0f}x. "
                 f"Measured: basic {basic:.3f}, least penetration {lp:.3f}, current {cur:.3f}: "
                 f"{ratio_text(res.ratio())} (least penetration below current: {lp < cur}).")
    lines.append("- The absolute values are not comparable with the paper's: its robot points and voxels are "
                 "its own (Move3D's PR2 surface samples); the ratio is.")
    early = float(np.mean(res.per_demo("least_penetration", "interference_unrecognised")[0]))
    if lp > 0:
        lines.append(f"- {100 * early / lp:.0f}% of least penetration's interference was accrued in steps planned "
                     "before the human's class was recognised (p < 0.5): the robot crosses the human's path while "
                     "the prediction is still spread over the classes (docs/experiments.md).")
    if basic == 0:
        lines.append("- Basic STOMP never enters the final prediction here: its path does not cross the predicted "
                     "human volume.")
    lines += ["", f"![interference]({png.name})", ""]
    return lines


def _switch_section(res: SwitchResult, png: Path) -> list[str]:
    lines = ["```", *res.lines(), "```", ""]
    lines.append(f"- verdict ({res.config.protocol} protocol, the step from which the robot leaves the human's cup "
                 f"for good): {switch_verdict(res)}.")
    p, c = res.median_settle("prediction"), res.median_settle("current")
    lines.append(f"- paper: prediction switches at step 4, current at step 13 (9 steps earlier). Measured median "
                 f"step from which each run keeps its final goal: prediction {p:g}, current {c:g} ({c - p:+g}).")
    ap, ac = res.median_away("prediction"), res.median_away("current")
    lines.append(f"- step from which the robot never again goes for the human's cup ({res.config.human_cup}; a run "
                 f"that ends there counts {res.config.timing.steps}), the verdict's measure: prediction {ap:g}, "
                 f"current {ac:g} ({ac - ap:+g}; target >= 5 earlier); runs ending at the human's cup: prediction "
                 f"{res.conflicts('prediction')}, current {res.conflicts('current')}.")
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
        lines.append(f"- final goal with {m}: "
                     + ", ".join(f"{k} in {v} run{'s' * (v != 1)}" for k, v in counts.items()))
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


def _table1_part(spec: str, prot: str, plan: ReportPlan, out: Path, common: dict[str, Any],
                 say: Callable[[str], None]) -> tuple[list[str], dict[str, Any]]:
    """A protocol's Table I: its Markdown (under the protocol's heading) and data."""
    t1 = run_interference(InterferenceConfig(scene=protocol(prot).table1_scene, demos=plan.table1_demos,
                                             seeds=plan.table1_seeds, **common), say, compile=plan.compile)
    png = plot_interference(t1, out / f"interference-{library_tag(spec)}{_suffix(prot)}.png")
    md = [f"### Protocol: {prot}", "", PROTOCOL_TEXT[prot], "",
          f"#### Interference (Table I), {prot} protocol", "", *_table1_section(t1, png)]
    return md, {"interference": t1.to_json(), "planning_ms": [r.planning_ms for r in t1.runs if not r.borrowed],
                "verdict": table1_verdict(t1)}


def _switch_part(spec: str, prot: str, plan: ReportPlan, out: Path, common: dict[str, Any],
                 say: Callable[[str], None]) -> tuple[list[str], dict[str, Any]]:
    """A protocol's goal switch, mirrored where the robot's first choice is the other cup: Markdown and data."""
    tag, suffix = library_tag(spec), _suffix(prot)
    sw = run_switch(SwitchConfig(demos=plan.switch_demos, **common), say, compile=plan.compile)
    png2 = plot_switch(sw, out / f"switch-{tag}{suffix}.png")
    md = [f"#### Goal switch (Fig. 8-9), {prot} protocol", "", *_switch_section(sw, png2)]
    first = {r.goals[0] for r in sw.runs if r.goals}
    mirrored = None
    if len(first) == 1 and sw.config.human_cup not in first:
        # the paper's situation: the human reaches for the cup the robot goes for first, so it must switch
        cup = first.pop()
        say(f"the robot first goes for {cup}, not {sw.config.human_cup}: the switch again with the human reaching "
            f"for {cup}")
        mirrored = run_switch(SwitchConfig(demos=plan.switch_demos, human_cup=cup, trials="cup", **common), say,
                              compile=plan.compile)
        png3 = plot_switch(mirrored, out / f"switch-mirrored-{tag}{suffix}.png")
        md += [f"#### Goal switch, the human reaching for {cup} (the robot's first choice), {prot} protocol", "",
               f"With an empty grid the robot first goes for {cup}, so with the human reaching for "
               f"{sw.config.human_cup} neither planner has a reason to switch. The paper's Fig. 8-9 has the human "
               "reach for the cup the robot first goes for; this run does the same here (the class nearest "
               f"{cup}).", "", *_switch_section(mirrored, png3)]
    return md, {"switch": sw.to_json(), "switch_mirrored": mirrored.to_json() if mirrored is not None else None,
                "planning_ms": [r.planning_ms for r in sw.runs + (mirrored.runs if mirrored else [])],
                "verdicts": {"switch": switch_verdict(sw),
                             "switch_mirrored": switch_verdict(mirrored) if mirrored is not None else None}}


def _protocol_data(table1: dict[str, Any], switch: dict[str, Any]) -> dict[str, Any]:
    """A protocol's section data from its Table I and switch parts (the report's JSON layout)."""
    return {"interference": table1["interference"], "switch": switch["switch"],
            "switch_mirrored": switch["switch_mirrored"],
            "planning_ms": {"K=1": table1["planning_ms"], "K=2": switch["planning_ms"]},
            "verdicts": {"table1": table1["verdict"], **switch["verdicts"]}}


def _suffix(prot: str) -> str:
    """The protocol's suffix of PNG names (none for the product's)."""
    return "" if prot == "product" else f"-{prot}"


PROTOCOL_TEXT = {
    "product": "The product's own: the robot follows its plan in time at 0.25 of the PR2's velocity limits, 0.5 s "
               "per step; costs integrated over time with the goal's dwell; the least total cost wins; Table I "
               "integrates over time; the product's Table I scene (`pr2_two_cups_side`) and the class nearest the "
               "human's cup.",
    "paper": "The authors' code (libmove3d-planners at its \"Paper submission\" commit): the robot executes 0.05 "
             "(side) / 0.085 (facing) of its path's configuration-space length per step and the rest after step "
             "20; STOMP with 10 rollouts of which 5 reused, 101 waypoints, 51 iterations; costs summed per "
             "waypoint; the least prediction cost wins; the swept volume of each class's regressed motion and a "
             "softmax of the mean per-frame log-likelihood; Table I integrated along the path; the authors' scene "
             "(`pr2_two_cups_side_parallel`) and, on the paper's library, the authors' motions (25-29, 77). "
             "docs/experiments.md lists every value and where it differs.",
}


PROTOCOL_PARTS = ("table1", "switch", "pace")
"""What each protocol's work is split into (``PROT:table1`` ...), so that the cores share it evenly."""


def part_names(protocols: tuple[str, ...]) -> list[str]:
    """A library's parts: ``recognition`` and, per protocol, its Table I, switch and pace sweep."""
    return ["recognition", *(f"{prot}:{what}" for prot in protocols for what in PROTOCOL_PARTS)]


def part_weight(part: str, plan: ReportPlan) -> float:
    """A part's expected planning work, to run the longest first: goal-steps planned, the paper protocol's x 1.6.

    Runs x goals (the switch: 2, and room for its mirrored run; Table I plans basic STOMP once per seed after
    the first, :mod:`services.experiments.reuse`); the paper protocol's step plans 101
    waypoints where the product's plans 40 (1.5-1.9x the time, docs/experiments.md "Run time"). The
    recognition plans nothing: 0, last.
    """
    if part == "recognition":
        return 0.0
    prot, what = part.split(":")
    n_paces = len((plan.paces or DEFAULT_PACES)[prot])
    runs = {"table1": plan.table1_demos * plan.table1_seeds * 2 + plan.table1_demos + plan.table1_seeds - 1,
            "switch": (plan.switch_demos or 25) * 2 * 2 * 2,
            "pace": n_paces * plan.pace_demos * plan.pace_seeds * 2}[what]
    return runs * (1.6 if prot == "paper" else 1.0)


def library_part(spec: str, part: str, plan: ReportPlan, out: Path, models_dir: Path, n_jobs: int = 2,
                 volume: str = DEFAULT_VOLUME) -> tuple[list[str], dict[str, Any]]:
    """One independent part of a library's section (one of :func:`part_names`), with its run time.

    Parts share nothing but the model cache (written atomically), so :func:`run_report` runs them in
    parallel (``report.report_workers``).

    Returns:
        ``(Markdown lines, data)``: for ``recognition`` the data has ``recognition`` and ``prediction_ms``; for
        ``PROT:table1`` ``interference``, ``planning_ms`` and ``verdict``; for ``PROT:switch`` ``switch``,
        ``switch_mirrored``, ``planning_ms`` and ``verdicts``; for ``PROT:pace`` ``pace_points``. Every part's data
        has ``seconds``, its wall time.
    """
    tag, started = library_tag(spec), time.monotonic()

    def say(line: str) -> None:  # the workers' lines interleave: each names its library and part
        print(f"[{tag} {part}] {line}", flush=True)

    if part == "recognition":
        lib = load_experiment_library(spec, load_scene(TABLE1_SCENE))
        say(f"recognition, leave-one-out on {lib.source}")
        lines, rec = _recognition(lib, plan, out, tag, n_jobs, models_dir)
        md, d = ([f"## Library: {lib.source}", "", "### Recognition (Fig. 6)", "", *lines],
                 {"recognition": rec, "prediction_ms": _prediction_ms(lib, models_dir, plan.components, volume)})
    else:
        prot, what = part.split(":")
        if what == "pace":
            say(f"Table I across the robot's pace ({prot} protocol)")
            pace = run_pace(PaceConfig(libraries=(spec,), protocols=(prot,), paces=plan.paces or dict(DEFAULT_PACES),
                                       demos=plan.pace_demos, draw=plan.table1_demos, seeds=plan.pace_seeds,
                                       timing=Timing(iterations=plan.iterations), components=plan.components,
                                       volume=volume, models_dir=models_dir, work_dir=out / "work" / prot),
                            say, compile=plan.compile)
            md, d = [], {"pace_points": pace.to_json()["points"]}
        else:
            common = {"library": spec, "timing": Timing(iterations=plan.iterations), "components": plan.components,
                      "models_dir": models_dir, "work_dir": out / "work",
                      "volume": volume if prot == "product" else None, "protocol": prot}
            md, d = (_table1_part if what == "table1" else _switch_part)(spec, prot, plan, out, common, say)
    d["seconds"] = time.monotonic() - started
    say(f"{part} done in {d['seconds']:.0f} s")
    return md, d


def library_section(spec: str, plan: ReportPlan, out: Path, models_dir: Path, n_jobs: int = 2,
                    volume: str = DEFAULT_VOLUME, protocols: tuple[str, ...] = PROTOCOLS,
                    parts: dict[str, tuple[list[str], dict[str, Any]]] | None = None
                    ) -> tuple[list[str], dict[str, Any]]:
    """Every experiment on one library under each protocol, and the pace sweep: its Markdown section and its data.

    The data: ``recognition``, ``prediction_ms``, ``pace`` (``foresight eval pace``'s JSON for this library),
    ``protocols`` (per protocol: ``interference``, ``switch``, ``switch_mirrored``, ``planning_ms``, ``verdicts``),
    and the first protocol's ``interference``, ``switch`` and ``planning_ms`` at the top level.

    Args:
        spec: ``synthetic`` or a library path.
        plan: The report's sizes (quick or full).
        out: Report directory (PNGs).
        models_dir: Held-out model cache.
        n_jobs: Worker processes of the recognition's leave-one-out.
        volume: The product protocol's occupancy volume.
        protocols: The protocols, in report order.
        parts: The :func:`library_part` results when they were made elsewhere (in parallel); missing ones are
            made here.
    """
    parts = dict(parts or {})
    for part in part_names(protocols):
        if part not in parts:
            parts[part] = library_part(spec, part, plan, out, models_dir, n_jobs, volume)
    md, head = list(parts["recognition"][0]), parts["recognition"][1]
    data: dict[str, Any] = {"recognition": head["recognition"], "protocols": {},
                            "part_seconds": {part: parts[part][1]["seconds"] for part in part_names(protocols)}}
    points: list[PacePoint] = []
    for prot in protocols:
        (t_md, table1), (s_md, switch) = parts[f"{prot}:table1"], parts[f"{prot}:switch"]
        md += [*t_md, *s_md]
        points += [PacePoint(p["protocol"], p["library"], p["pace"], p["ratio"],
                             {k: p[k] for k in ("basic", "least_penetration")})
                   for p in parts[f"{prot}:pace"][1]["pace_points"]]
        data["protocols"][prot] = _protocol_data(table1, switch)
    data.update({k: data["protocols"][protocols[0]][k] for k in ("interference", "switch", "planning_ms")})
    pace = PaceResult(PaceConfig(libraries=(spec,), protocols=protocols, demos=plan.pace_demos, seeds=plan.pace_seeds))
    pace.points = points
    data["pace"] = pace.to_json()
    data["prediction_ms"] = head["prediction_ms"]
    return md, data
