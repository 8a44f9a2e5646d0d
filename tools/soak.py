"""``foresight bench soak``: human poses at 300 Hz for 60 s through the real-time system, as processes.

A system check, not a speed benchmark: it runs no baseline to compare with and prints no ratio; its figures say
whether the system as a whole keeps up under load on this machine (a latency that grows, poses dropped, a
replanning period that stretches, memory that grows), to be read against the real-time budgets.

Once the robot moves (the planner is up), for ``--duration-s`` seconds the watcher (:mod:`tools.system`)
records every pose, occupancy grid, plan and robot state. It prints:

* the predictor's latency, pose received -> its occupancy grid received (p50 / p99 / max, and p50 of
  the first and the last tenth of the window: a growing latency is a growing backlog), and how many
  poses of the window got no grid of their own by its end (coalesced when the predictor was behind,
  dropped, or still queued);
* the reaction latency: pose received -> the first grid received for it or a later pose of its
  demonstration (what the planner waits for when the predictor grids only the newest pose);
* the replanning period (between plans received: p50 / p99 / max) and the plans' planning time;
* the share of robot states that held, and why;
* the resident memory (RSS) of every process at the start and the end of the window.

It exits 1 when a process was not running at the window's end, with a line each (how it ended, its log).
"""

from __future__ import annotations

import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from services.executor.core import reason_kind
from services.processes import describe_exit
from services.replayer.core import MAX_RATE_HZ, MIN_RATE_HZ
from shared import strict_json
from shared.arguments import ArgumentParser, DefaultsHelpFormatter
from shared.runtime import cli_errors, help_text, interruptible, setup_logging

from .faults import demo_model
from .system import ProcessSystem, SystemSpec, Watcher, positive_number

__all__ = ["soak", "summarise", "exit_lines", "main"]


def _pct(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"p50": None, "p99": None, "max": None}
    a = np.asarray(values)
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "max": float(a.max())}


def _cover_latency(poses: list[tuple[float, Any]], grids: list[tuple[float, Any]]) -> list[float]:
    """Per pose, seconds until a grid for it or a later pose of its demonstration was received (if one was)."""
    by_demo: dict[int, list[tuple[float, int]]] = {}
    for t, g in grids:
        by_demo.setdefault(g.demo_id, []).append((t, g.index))
    arrays = {d: np.array(sorted(v)).T for d, v in by_demo.items()}  # (2, G): receive times, indices
    out = []
    for t, m in poses:
        if m.demo_id not in arrays:
            continue
        tg, ig = arrays[m.demo_id]
        start = int(np.searchsorted(tg, t))
        hit = np.flatnonzero(ig[start:] >= m.index)
        if len(hit):
            out.append(float(tg[start + hit[0]] - t))
    return out


def summarise(watcher: Watcher, t0: float, t1: float) -> dict[str, Any]:
    """The window ``[t0, t1]`` (monotonic s) of what the watcher recorded."""
    poses = [(t, m) for t, m in watcher.snapshot(watcher.poses) if t0 <= t <= t1]
    grids = [(t, m) for t, m in watcher.snapshot(watcher.occupancy) if t >= t0]
    occ = {(m.demo_id, m.index): t for t, m in grids}
    lat = [(t, occ[(m.demo_id, m.index)] - t) for t, m in poses if (m.demo_id, m.index) in occ]
    cover = _cover_latency(poses, grids)
    n = len(lat)
    tenth = max(1, n // 10)
    plans = [(t, m) for t, m in watcher.snapshot(watcher.plans) if t0 <= t <= t1]
    periods = [b[0] - a[0] for a, b in zip(plans, plans[1:], strict=False)]
    states = [m for t, m in watcher.snapshot(watcher.states) if t0 <= t <= t1]
    held = Counter(reason_kind(s.reason) for s in states if s.holding)
    return {
        "window_s": t1 - t0, "poses": len(poses), "pose_rate_hz": len(poses) / (t1 - t0) if t1 > t0 else 0.0,
        "occupancy_received": sum(1 for t, _ in grids if t <= t1), "occupancy_for_poses": n,
        "dropped": len(poses) - n,
        "latency_s": _pct([x for _, x in lat]),
        "latency_first_tenth_p50_s": _pct([x for _, x in lat[:tenth]])["p50"],
        "reaction_latency_s": _pct(cover), "poses_never_covered": len(poses) - len(cover),
        "latency_last_tenth_p50_s": _pct([x for _, x in lat[-tenth:]])["p50"],
        "plans": len(plans), "replan_period_s": _pct(periods),
        "planning_ms": _pct([m.planning_ms for _, m in plans]),
        "states": len(states), "held_share": sum(held.values()) / len(states) if states else 0.0,
        "held_reasons": dict(held),
    }


def soak(system: ProcessSystem, watcher: Watcher, duration_s: float, timeout: float = 240.0,
         progress: Callable[[str], None] = lambda _line: None) -> dict[str, Any]:
    """Wait for the robot to move, then measure ``duration_s`` seconds (a line every 10 s); RSS at both ends."""
    progress(f"soak: waiting for the robot to move (at most {timeout:g} s)")
    system.wait_moving(watcher, timeout)
    t0 = time.monotonic()
    rss0 = system.rss()
    progress(f"soak: the robot moves; measuring {duration_s:g} s")
    while (left := t0 + duration_s - time.monotonic()) > 0:  # it slept the whole window without a word
        time.sleep(min(10.0, left))
        if time.monotonic() < t0 + duration_s:
            n = sum(1 for t, _ in watcher.snapshot(watcher.poses) if t >= t0)  # the window's, not since the watcher
            progress(f"soak: {time.monotonic() - t0:.0f} / {duration_s:g} s, {n} poses in the window")
    t1 = time.monotonic()
    rss1 = system.rss()
    out = summarise(watcher, t0, t1)
    out["rss_mb"] = {n: {"start": rss0.get(n, 0.0), "end": rss1.get(n, 0.0)} for n in system.procs}
    out["running"] = {n: p.running for n, p in system.procs.items()}
    out["exited"] = {n: {"status": p.returncode, "log": str(p.log_path)} for n, p in system.procs.items()
                     if not p.running}
    return out


def exit_lines(exited: dict[str, dict[str, Any]]) -> list[str]:
    """One line per process not running at the window's end: how it ended and its log (the exit status said 1 alone)."""
    return [f"{n} was not running at the window's end: "
            f"{'it ' + describe_exit(e['status']) if e['status'] is not None else 'never started'}; its log: {e['log']}"
            for n, e in exited.items()]


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x * 1e3:.0f} ms"


def _fmt(d: dict[str, float | None], scale: float = 1e3, unit: str = "ms") -> str:
    return " / ".join("-" if d[k] is None else f"{d[k] * scale:.0f}" for k in ("p50", "p99", "max")) + f" {unit}"


def main(argv: list[str] | None = None, prog: str = "foresight bench soak") -> int:
    """Run the soak; returns 0 when every process was still running at the end (else 1, a line each on stderr)."""
    p = ArgumentParser(prog=prog, description=help_text(__doc__), formatter_class=DefaultsHelpFormatter)
    p.add_argument("--rate-hz", type=positive_number(MIN_RATE_HZ, MAX_RATE_HZ, inclusive=True), default=300.0,
                   help="poses per second")
    p.add_argument("--duration-s", type=positive_number(), default=60.0, help="measured window")
    p.add_argument("--timeout", type=positive_number(), default=240.0, help="longest wait for the robot to move (s)")
    p.add_argument("--run-dir", type=Path, default=Path("runs/soak"), help="logs and the MCAP")
    p.add_argument("--models-dir", type=Path, default=Path("models"), help="model cache")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args(argv)
    setup_logging("WARNING")
    with cli_errors(prog):
        spec = SystemSpec(run_dir=args.run_dir, model=demo_model(args.models_dir), rate_hz=args.rate_hz)
        system = ProcessSystem(spec)
        try:  # SIGTERM as Ctrl-C: the processes are closed below, none left behind
            with interruptible(threading.Event()):
                system.start_router()  # before the watcher: opened first, it warned the router was unreachable
            with interruptible(threading.Event()), Watcher(system.endpoint, poses=True) as watcher:
                system.start_services()
                r = soak(system, watcher, args.duration_s, args.timeout,
                         progress=lambda line: print(line, file=sys.stderr, flush=True))
        finally:
            r_exit = system.close()
    r["exit"] = r_exit
    if args.json:
        print(strict_json.dumps(r))
    else:
        print(f"window {r['window_s']:.1f} s: {r['poses']} poses ({r['pose_rate_hz']:.0f} Hz), "
              f"{r['occupancy_received']} occupancy grids received, of them for the window's poses "
              f"{r['occupancy_for_poses']}; poses without a grid of their own by the end: {r['dropped']}")
        print(f"predictor latency p50/p99/max {_fmt(r['latency_s'])}; p50 first tenth "
              f"{_ms(r['latency_first_tenth_p50_s'])}, last tenth {_ms(r['latency_last_tenth_p50_s'])}")
        print(f"reaction latency (pose -> a grid for it or a later pose) p50/p99/max "
              f"{_fmt(r['reaction_latency_s'])}; poses never covered: {r['poses_never_covered']}")
        print(f"plans {r['plans']}: period p50/p99/max {_fmt(r['replan_period_s'])}, planning "
              f"{_fmt(r['planning_ms'], 1.0)}")
        print(f"states {r['states']}, held {100 * r['held_share']:.1f}% {r['held_reasons']}")
        for n, m in r["rss_mb"].items():
            print(f"rss {n:<9} {m['start']:.0f} MB -> {m['end']:.0f} MB")
    for line in exit_lines(r["exited"]):
        print(f"{prog}: {line}", file=sys.stderr)
    return 0 if all(r["running"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
