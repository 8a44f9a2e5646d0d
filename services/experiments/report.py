"""``foresight eval all --out DIR``: every experiment and the timings, one Markdown report with its PNGs.

For each library (default: the synthetic one and, when it is beside the repository, the paper's):
recognition (Fig. 6), then under each protocol (``--protocols``, default both: the product's and the paper
authors', :mod:`services.experiments.protocol`) interference (Table I) and the goal switch (Fig. 8-9), then
Table I across the robot's pace (:mod:`services.experiments.pace`) and the timings (planning ms per step from
every run, prediction ms per pose). A summary sets the paper's numbers, the paper protocol's and the product
protocol's side by side with a verdict for each (:mod:`services.experiments.verdicts`); docs/experiments.md
explains the differences.

``--quick`` (run in CI): the synthetic library only, 4 Gaussians per class, recognition on 4 demonstrations per
class, Table I with 1 demonstration x 2 seeds, the switch with 2 demonstrations, 20 STOMP iterations per step,
the pace sweep at each protocol's own pace only, the cost evaluated eagerly (no compile). The full report (20
Gaussians, 5 demonstrations x 10 seeds, every demonstration of the class, each protocol's iterations, five paces
per protocol with 3 demonstrations) runs in parts (each library's recognition, and each protocol's Table I,
switch and pace sweep), in one worker process per core plus one (``--workers``), the longest expected first
(docs/experiments.md, "Run time"). ``--volume`` picks the product protocol's occupancy volume.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from services.predictor.volumes import DEFAULT_VOLUME, VOLUMES
from shared import strict_json
from shared.library import load_library, report_drops
from shared.library.report import said_once, say_once
from shared.native_threads import limit_blas_threads
from shared.runtime import UserError

from .planners import Timing
from .protocol import PROTOCOLS

__all__ = ["ReportPlan", "QUICK", "FULL", "add_report_arguments", "run_report", "run_parts", "PAPER_LIBRARY"]

T = TypeVar("T")

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
    iterations: int | None  # None: each protocol's (50 / 51)
    compile: bool
    pace_demos: int  # the pace sweep: demonstrations x seeds per point
    pace_seeds: int
    paces: dict[str, tuple[float, ...]] | None = None  # None: every pace of DEFAULT_PACES


FULL = ReportPlan(components=20, recognition_demos=0, table1_demos=5, table1_seeds=10, switch_demos=0,
                  iterations=None, compile=True, pace_demos=3, pace_seeds=1)
QUICK = ReportPlan(components=4, recognition_demos=4, table1_demos=1, table1_seeds=2, switch_demos=2,
                   iterations=20, compile=False, pace_demos=1, pace_seeds=1,
                   paces={"product": (0.25,), "paper": (0.05,)})


def add_report_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``foresight eval all``."""
    p.add_argument("--out", type=Path, default=Path("runs/report"), help="report directory (default: runs/report)")
    p.add_argument("--quick", action="store_true", help="the small variant (about 4 minutes on 2 cores; see above)")
    p.add_argument("--libraries", default="", help="comma-separated libraries ('synthetic' or paths); default: "
                   "synthetic and the paper's library when it is at ../shared/data/paper-library (--quick: "
                   "synthetic only)")
    p.add_argument("--library", default="", metavar="PATH", help="the paper's motion library (a directory of "
                   "compound_*.csv, github.com/jmainpri/gmm-gmr data/gestures/8classes_rafi1, or an .npz): run it "
                   "beside the synthetic library (the same as --libraries synthetic,PATH)")
    p.add_argument("--models-dir", type=Path, default=Path("models/experiments"), help="held-out models cache")
    p.add_argument("--volume", choices=VOLUMES, default=DEFAULT_VOLUME, help="occupancy volume of the held-out "
                   f"prediction models of the product protocol (foresight train --volume; default: {DEFAULT_VOLUME}; "
                   "the paper protocol always uses the paper's: paper)")
    p.add_argument("--protocols", default="product,paper", help="comma-separated protocols run side by side "
                   "(default: product,paper; docs/experiments.md)")
    p.add_argument("--workers", type=int, default=0, help="worker processes for the parts (default 0: one per "
                   "core plus one, since a lock-step run leaves its core idle while its messages travel; "
                   "docs/experiments.md, 'Run time')")


def _command(args: argparse.Namespace, out: Path) -> str:
    """The command line of this report: every option given a value other than its default.

    ``--libraries``, ``--library``, ``--models-dir`` and ``--workers`` were left out of it.
    """
    parser = argparse.ArgumentParser()
    add_report_arguments(parser)
    words = ["foresight", "eval", "all", "--out", str(out)]
    for dest, default in vars(parser.parse_args([])).items():  # the options of eval all, in their order
        value = getattr(args, dest, default)
        if dest != "out" and value != default:
            flag = "--" + dest.replace("_", "-")
            words += [flag] if value is True else [flag, str(value)]
    return shlex.join(words)


def report_workers(asked: int = 0) -> int:
    """The report's worker processes: ``asked``, or (0) one per core plus one.

    A lock-step run is a chain of messages between four services: while they travel, its process waits and
    its core idles (the report at 2bb0292 kept its 2 workers busy for 2 x 1976 s and used 3354 CPU-seconds of
    them, 85 %). One worker more fills those gaps: 2, 3 and 4 copies of one paper-protocol Table I command
    (12 runs each, models cached) at once ran 0.44-0.47, 0.50 and 0.53 runs per second on this project's
    2-core machine, the same numbers in every copy (docs/experiments.md, "Run time").

    Raises:
        UserError: If ``asked`` is negative.
    """
    if asked < 0:
        raise UserError(f"--workers must be >= 0 (0: one per core plus one), got {asked}")
    return asked or (os.cpu_count() or 1) + 1


def run_parts(fn: Callable[..., T], jobs: Sequence[tuple[Any, ...]], workers: int, context: str = "spawn",
              said: Sequence[str] = ()) -> list[T]:
    """``fn(*job)`` for every job in ``workers`` processes, handed out in the order given; results in that order.

    The first job to raise ends them all: its exception is raised here at once, and the worker processes, with the
    jobs they are running, are terminated (a full report's parts run for minutes; waiting for them would only
    delay the error). ``context``: the multiprocessing start method. ``said``: the libraries' drop lines the
    caller logged already; the workers do not repeat them (:func:`shared.library.report.say_once`).
    """
    results: list[Any] = [None] * len(jobs)
    with multiprocessing.get_context(context).Pool(workers, initializer=_worker_init,
                                                   initargs=(tuple(said),)) as pool:  # exit: terminate
        for i, result in pool.imap_unordered(_indexed, [(fn, i, job) for i, job in enumerate(jobs)]):
            results[i] = result
        pool.close()  # done: the workers exit by themselves (terminate is for a failure)
        pool.join()
    return results


def _worker_init(said: tuple[str, ...]) -> None:
    limit_blas_threads()
    say_once(said)


def _indexed(task: tuple[Callable[..., Any], int, tuple[Any, ...]]) -> tuple[int, Any]:
    fn, i, job = task
    return i, fn(*job)


def _left_out(args: argparse.Namespace, libs: list[str]) -> list[str]:
    """A line saying why the paper's library is not in the report, where the user did not choose the libraries."""
    if args.library or args.libraries or str(PAPER_LIBRARY) in libs:
        return []
    why = ("a --quick run leaves it out (`--library PATH` adds it)" if PAPER_LIBRARY.is_dir() else
           f"it is not at {PAPER_LIBRARY} (the README's 'The paper's motion library' says where to get it)")
    return [f"The paper's library is not in this report: {why}.", ""]


def run_report(args: argparse.Namespace) -> int:
    """Run every experiment and write ``report.md`` and its PNGs to ``args.out``; returns 0.

    Each library's recognition and each protocol run as separate parts in worker processes (:func:`report_workers`).
    """
    # the experiments load the services and torch: imported to run, not for foresight eval --help
    from .heldout import SYNTHETIC, library_tag
    from .pace import PaceConfig, PacePoint, PaceResult, plot_pace
    from .sections import library_part, library_section, part_names, part_weight
    from .verdicts import summary

    plan = QUICK if args.quick else FULL
    protocols = tuple(p.strip() for p in args.protocols.split(",") if p.strip())
    bad = [p for p in protocols if p not in PROTOCOLS]
    if bad or not protocols:
        raise UserError(f"--protocols: {', '.join(bad) or 'none given'}; choose from {', '.join(PROTOCOLS)}")
    libs = [s.strip() for s in args.libraries.split(",") if s.strip()]
    if args.library:
        if libs:
            raise UserError("give --library PATH or --libraries A,B, not both")
        if not Path(args.library).exists():
            raise UserError(f"--library: {args.library} not found (the paper's library: a directory of "
                            "compound_*.csv, see the README's 'The paper's motion library')")
        libs = [SYNTHETIC, args.library]
    if not libs:
        libs = [SYNTHETIC] + ([] if args.quick or not PAPER_LIBRARY.is_dir() else [str(PAPER_LIBRARY)])
    tags = [library_tag(spec) for spec in libs]
    if clash := sorted({t for t in tags if tags.count(t) > 1}):  # one name per library in file names and keys
        raise UserError(f"--libraries: {len(libs)} libraries but the name {clash[0]!r} is given twice ("
                        f"{', '.join(s for s, t in zip(libs, tags, strict=True) if t == clash[0])}); the report "
                        "names each library by its folder's name: give each library a different folder name")
    asked = report_workers(args.workers)  # before the directory: --workers -1 left an empty one behind
    started = time.monotonic()
    # every part reads its library again: read each here first (a bad one fails before any work and before the
    # directory is made), say what it dropped, and let no part say it again
    said = [line for spec in libs if spec != SYNTHETIC for line in report_drops(load_library(spec, report=False))]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    timing = Timing(iterations=plan.iterations)
    # every library's recognition and each protocol are independent parts: one worker process per core
    jobs = [(spec, part) for spec in libs for part in part_names(protocols)]
    workers = min(len(jobs), asked)
    done: dict[str, dict[str, tuple[list[str], dict[str, Any]]]] = {spec: {} for spec in libs}
    with said_once(said):
        if workers > 1:
            order = sorted(jobs, key=lambda job: -part_weight(job[1], plan))  # the longest first: cores end together
            results = run_parts(library_part, [(spec, part, plan, out, Path(args.models_dir), 1, args.volume)
                                               for spec, part in order], workers, said=said)
            for (spec, part), result in zip(order, results, strict=True):
                done[spec][part] = result
        # the parts not made in workers are made here: --workers 1 ran the recognition in 2 processes all the same
        sections = [library_section(spec, plan, out, Path(args.models_dir), n_jobs=workers, volume=args.volume,
                                    protocols=protocols, parts=done[spec]) for spec in libs]
    pace = PaceResult(PaceConfig(libraries=tuple(libs), protocols=protocols, demos=plan.pace_demos,
                                 seeds=plan.pace_seeds))
    for _, d in sections:
        pace.points += [PacePoint(p["protocol"], p["library"], p["pace"], p["ratio"],
                                  {k: p[k] for k in ("basic", "least_penetration")}) for p in d["pace"]["points"]]
    pace_png = plot_pace(pace, out / "pace.png")
    iterations = (f"{timing.iterations} STOMP iterations" if timing.iterations else
                  "50 STOMP iterations in the product protocol (51 in the paper's)")
    md = [f"# Foresight: the paper's experiments ({'quick' if args.quick else 'full'} run)", "",
          f"Command: `{_command(args, out)}`. Every run: "
          f"{timing.steps} steps of {timing.period_s} s, "
          f"{iterations}, {plan.components} Gaussians per class; the product protocol's occupancy "
          f"volume `{args.volume}` (`foresight train --volume`; the paper protocol's is `paper`). Why the numbers "
          "differ from the paper's: docs/experiments.md.", "", *_left_out(args, libs),
          *(verdicts := summary(libs, sections, protocols)),
          "## Across the robot's pace", "", "```", *pace.lines(), "```", "", f"![pace]({pace_png.name})", ""]
    data: dict[str, Any] = {"plan": plan.__dict__, "volume": args.volume, "protocols": protocols, "libraries": {},
                            "pace": pace.to_json()}
    planning: dict[str, list[float]] = {f"{k}, {prot} protocol": [] for prot in protocols for k in ("K=1", "K=2")}
    for spec, (lines, d) in zip(libs, sections, strict=True):
        md += lines
        data["libraries"][library_tag(spec)] = d
        for prot in protocols:
            for k in ("K=1", "K=2"):
                planning[f"{k}, {prot} protocol"] += d["protocols"][prot]["planning_ms"][k]
    how = (f"as {len(jobs)} parts (each library's recognition, and each protocol's Table I, switch and pace sweep) "
           f"in {workers} worker processes on {os.cpu_count() or 1} cores, the longest expected first (the planning "
           "times below are measured there, the workers sharing the cores)" if workers > 1
           else "in one process")
    md += ["## Timing", "", f"{len(libs)} {'library' if len(libs) == 1 else 'libraries'} ran {how}.", "",
           "| measure | median | p90 | samples |", "|---|---|---|---|"]
    for k, v in planning.items():
        if v:
            md.append(f"| planning ms per step, {k} (median of each run) | {np.median(v):.1f} | "
                      f"{np.percentile(v, 90):.1f} | {len(v)} runs |")
    for tag, d in data["libraries"].items():
        p = d["prediction_ms"]
        md.append(f"| prediction ms per pose ({tag}) | {p['median_ms']:.2f} | {p['p90_ms']:.2f} | {p['poses']} poses |")
    md += ["", "The paper: about 500 ms per replanning step for one goal (50 iterations).", "",
           "Each part's run time (s; the parts ran in parallel, so their sum is the cores' busy time):", "",
           f"| library | {' | '.join(names := part_names(protocols))} | sum |", f"|---{'|---' * (len(names) + 1)}|"]
    for tag, d in data["libraries"].items():
        secs = [d["part_seconds"][part] for part in names]
        md.append(f"| {tag} | {' | '.join(f'{v:.0f}' for v in secs)} | {sum(secs):.0f} |")
    md += ["", f"Report made in {time.monotonic() - started:.0f} s.", ""]
    (out / "report.md").write_text("\n".join(md))
    (out / "report.json").write_text(strict_json.dumps(data))
    print("eval all: the paper's results, reproduced or not (the tables, plots and causes: report.md):",
          *(f"  {line[2:].replace('**', '')}" for line in verdicts if line.startswith("- ")), sep="\n")
    print(f"eval all: wrote {out / 'report.md'} and its PNGs in {time.monotonic() - started:.0f} s", flush=True)
    return 0

