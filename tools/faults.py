"""``foresight bench faults``: kill -9 each service (and the router) of a moving robot's run, measure the hold.

A system check, not a speed benchmark: it runs no baseline to compare with and prints no ratio; what counts is
that the robot holds when a service dies, moves again when it is back, never moves on stale inputs, and that the
executor's MCAP is read back; its latencies say how soon, on this machine.

A real-time run as processes (:mod:`tools.system`; the replayer loops, the executor runs until
stopped). For each victim in turn, once the robot moves: SIGKILL it, record when the robot's state
first says ``holding`` (and why), start it again after ``--down-s``, record when its liveliness token
is back and when the robot moves again. Over the whole run, every state that is not holding is checked
against the inputs the watcher saw: the newest plan and occupancy must be younger than the stale
limit (plus ``SLACK_S`` for the watcher's own delivery). Last, SIGKILL the executor and read each of its
MCAPs back (``run.mcap``, and ``run-<n>.mcap`` per restart when it was a victim) with the reader ``foresight log
info`` uses (how much it recovered).

Prints one line per victim (hold latency after the kill, resume latency after the service's return),
the release check and one line per MCAP; ``--json`` prints one object. Exits 1 when the robot moved while a
service was down (the router aside: the services talk peer to peer without it).
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from shared import strict_json
from shared.arguments import ArgumentParser, DefaultsHelpFormatter
from shared.recording.reader import read_log
from shared.runtime import cli_errors, help_text, interruptible, setup_logging

from .system import PROCESSES, ProcessSystem, SystemSpec, Watcher, positive_number

__all__ = ["measure_kill", "stale_releases", "recover_after_kill", "read_back", "executor_mcaps",
           "moved_failures", "demo_model", "main", "SLACK_S"]

SLACK_S = 0.1
"""Allowance (s) for the watcher seeing a message later or earlier than the executor does."""


def _say_training(path: Path) -> None:
    print(f"foresight bench: training the prediction model once, about a minute; later runs load it from {path}",
          file=sys.stderr, flush=True)


def demo_model(models_dir: Path, components: int = 4, on_train: Callable[[Path], None] = _say_training) -> Path:
    """The prediction model of the embedded synthetic library (cached in ``models_dir``).

    Args:
        models_dir: The model cache.
        components: Gaussians per class.
        on_train: Called with the model's path before it is trained (not when cached): by default one line on
            stderr, as the minute of training passed without a word.
    """
    from services.scenario import choose_demonstration, model_for
    from shared.scene import load_scene
    from shared.synthetic import generate_library

    scene = load_scene(None)
    lib = generate_library(seed=0, scene=scene)
    demo = choose_demonstration(lib, 20, 0).demo
    return model_for(lib, scene, demo, models_dir, components=components, progress=False, on_train=on_train)


def _first(items: list, after: float, pred: Any) -> tuple[float, Any] | None:
    return next(((t, m) for t, m in items if t > after and pred(m)), None)


def measure_kill(system: ProcessSystem, watcher: Watcher, victim: str, down_s: float = 3.0,
                 timeout: float = 240.0) -> dict[str, Any]:
    """Kill ``victim`` while the robot moves, start it again after ``down_s``; what the robot did.

    Returns:
        ``victim``; ``hold_s`` (kill -> first holding state, None: never held) and ``hold_reason``;
        ``moved_while_down`` (states not holding between the hold and the restart; with no hold before the
        restart, between the kill and the restart); ``back_s`` (restart -> liveliness token back; the router,
        which has none: restart -> its port takes connections; None: the token never came back);
        ``resume_s`` (token back -> first state not holding after the restart), ``resume_after_start_s``
        and ``resume_after_output_s`` (its first plan or occupancy after its return -> moving); ``events``
        in order.
    """
    system.wait_moving(watcher, timeout, before=f" (before killing {victim})")
    t_kill = time.monotonic()
    system.kill(victim)
    watcher.wait(lambda: _first(watcher.snapshot(watcher.states), t_kill, lambda m: m.holding) is not None,
                 min(down_s, 10.0))
    time.sleep(max(0.0, down_s - (time.monotonic() - t_kill)))
    t_start = time.monotonic()
    t_router = t_start
    if victim == "router":  # no token: back when its port takes connections (start() returned at once: 0.00 s)
        system.start_router(timeout)
        t_router = time.monotonic()
    else:
        system.start(victim)
        watcher.wait(lambda: any(t > t_start and s == victim and up for t, s, up in watcher.snapshot(watcher.tokens)),
                     timeout)
    token = next((t for t, s, up in watcher.snapshot(watcher.tokens) if t > t_start and s == victim and up), None)
    back = t_router if victim == "router" else t_start if token is None else token
    watcher.wait(lambda: _first(watcher.snapshot(watcher.states), back, lambda m: not m.holding) is not None, timeout)
    states = watcher.snapshot(watcher.states)
    hold = _first(states, t_kill, lambda m: m.holding)
    resume = _first(states, max(back, hold[0] if hold else t_kill), lambda m: not m.holding)
    down_from = hold[0] if hold and hold[0] < t_start else t_kill  # never held while down: every state moved
    moved = sum(1 for t, m in states if down_from < t < t_start and not m.holding)
    outputs = {"predictor": watcher.occupancy, "planner": watcher.plans}.get(victim)
    first_out = next((t for t, _ in watcher.snapshot(outputs) if t > back), None) if outputs is not None else None
    events = [("kill", 0.0)]
    if hold:
        events.append(("hold", hold[0] - t_kill))
    returned = token is not None or victim == "router"
    events.append(("restart", t_start - t_kill))
    if returned:
        events.append(("back", back - t_kill))
    if resume:
        events.append(("resume", resume[0] - t_kill))
    return {"victim": victim, "hold_s": hold[0] - t_kill if hold else None,
            "hold_reason": hold[1].reason if hold else "", "moved_while_down": moved,
            "back_s": back - t_start if returned else None, "resume_s": resume[0] - back if resume else None,
            "resume_after_start_s": resume[0] - t_start if resume else None,
            "resume_after_output_s": resume[0] - first_out if resume and first_out else None,
            "events": sorted(events, key=lambda e: e[1])}


def stale_releases(watcher: Watcher, limit: float, slack: float = SLACK_S) -> list[dict[str, Any]]:
    """States that were not holding although the newest plan or occupancy the watcher had seen was stale.

    A state counts at its stamp (the wall time its ``q`` is for: the executor's run start on its wall clock plus its
    own clock, which it judged staleness at; a state period or so before it published it), the inputs at their
    arrival at the watcher; ``slack`` allows for the two deliveries differing.
    """
    plans = [t for t, _ in watcher.snapshot(watcher.plans)]
    occ = [t for t, _ in watcher.snapshot(watcher.occupancy)]
    out = []
    for _, st in watcher.snapshot(watcher.states):
        if st.holding:
            continue
        t = st.stamp - watcher.wall_offset  # when the executor judged it (its wall clock, on this machine's)
        last_plan = max((p for p in plans if p <= t), default=None)
        last_occ = max((o for o in occ if o <= t), default=None)
        ages = {"plan": None if last_plan is None else t - last_plan,
                "occupancy": None if last_occ is None else t - last_occ}
        stale = {k: a for k, a in ages.items() if a is not None and a > limit + slack}
        if stale:
            out.append({"t": t, **stale})
    return out


def read_back(path: Path) -> dict[str, Any]:
    """What the reader ``foresight log info`` uses recovers of one MCAP (up to its last complete chunk)."""
    lf = read_log(path)
    lasts = [c.last_time for c in lf.channels.values() if c.last_time is not None]
    firsts = [c.first_time for c in lf.channels.values() if c.first_time is not None]
    return {"path": str(path), "size_bytes": lf.size, "complete": lf.complete, "error": lf.error,
            "messages": lf.message_count, "channels": len(lf.channels),
            "duration_s": (max(lasts) - min(firsts)) / 1e9 if lasts else 0.0}


def recover_after_kill(system: ProcessSystem) -> dict[str, Any]:
    """SIGKILL the executor and read its newest MCAP back (up to the last complete chunk)."""
    system.kill("executor")
    return read_back(system.mcap_path)


def executor_mcaps(system: ProcessSystem) -> list[Path]:
    """Every MCAP the executor wrote in this check: ``run.mcap``, then ``run-<n>.mcap`` per restart, oldest first.

    Counted from its starts, not globbed: an earlier check's ``run-<n>.mcap`` in the same folder is not this one's.
    """
    n = system.starts.get("executor", 0) if system.spec.mcap else 0
    return [system.spec.mcap_path] + [system.spec.run_dir / f"run-{i}.mcap" for i in range(1, n)] if n else []


def moved_failures(kills: list[dict[str, Any]]) -> list[str]:
    """One line per victim the robot moved while it was down for (the router aside: no hold is needed without it)."""
    def held(k: dict[str, Any]) -> str:
        return "never held" if k["hold_s"] is None else f"held {k['hold_s']:.2f} s after the kill"

    return [f"the robot moved {k['moved_while_down']} states while the {k['victim']} was down ({held(k)})"
            for k in kills if k["victim"] != "router" and k["moved_while_down"]]


def _line(r: dict[str, Any]) -> str:
    def f(x: float | None) -> str:
        return "-" if x is None else f"{x:.2f} s"

    router = " (no hold needed: the services talk peer to peer)" if r["victim"] == "router" else ""
    return (f"  {r['victim']:<9}  hold {f(r['hold_s'])} after kill ({r['hold_reason'] or 'never held'}); "
            f"moved while down: {r['moved_while_down']} states{router}; back {f(r['back_s'])} after restart; "
            f"resume {f(r['resume_s'])} after its return ({f(r['resume_after_start_s'])} after its start, "
            f"{f(r.get('resume_after_output_s'))} after its first output)")


def main(argv: list[str] | None = None, prog: str = "foresight bench faults") -> int:
    """Run the fault injection; returns 0 when it ran (the numbers are the result), 1 when the robot moved.

    The robot moving while a service other than the router was down is the failure (a line each on stderr).
    """
    p = ArgumentParser(prog=prog, description=help_text(__doc__), formatter_class=DefaultsHelpFormatter)
    p.add_argument("--victims", default="predictor,planner,replayer,router",
                   help=f"what to kill, in order (comma-separated, of {', '.join(PROCESSES)})")
    p.add_argument("--down-s", type=positive_number(inclusive=True), default=3.0, help="seconds each victim stays dead")
    p.add_argument("--run-dir", type=Path, default=Path("runs/faults"), help="logs and the MCAP")
    p.add_argument("--models-dir", type=Path, default=Path("models"), help="model cache")
    p.add_argument("--timeout", type=positive_number(), default=240.0, help="longest wait for any one event (s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args(argv)
    victims = [v.strip() for v in args.victims.split(",") if v.strip()]
    unknown = [v for v in victims if v not in PROCESSES]
    if unknown or not victims:
        p.error(f"--victims {args.victims!r}: {'unknown ' + ', '.join(map(repr, unknown)) if unknown else 'empty'}"
                f" (choose from {', '.join(PROCESSES)})")
    setup_logging("WARNING")
    with cli_errors(prog):
        spec = SystemSpec(run_dir=args.run_dir, model=demo_model(args.models_dir))
        system = ProcessSystem(spec)
        results: dict[str, Any] = {"kills": []}
        try:  # SIGTERM as Ctrl-C: the processes are closed below, none left behind
            with interruptible(threading.Event()):
                system.start_router()  # before the watcher: opened first, it warned the router was unreachable
            with interruptible(threading.Event()), Watcher(system.endpoint) as watcher:
                system.start_services()
                for victim in victims:
                    r = measure_kill(system, watcher, victim, args.down_s, args.timeout)
                    results["kills"].append(r)
                    if not args.json:
                        print(_line(r), flush=True)
                results["stale_releases"] = stale_releases(watcher, spec.stale_limit_s)
                system.kill("executor")
                results["mcap"] = [read_back(path) for path in executor_mcaps(system)]
        finally:
            results["exit"] = system.close()
    results["failures"] = moved_failures(results["kills"])
    if args.json:
        print(strict_json.dumps(results))
    else:
        print(f"  releases with an input older than {spec.stale_limit_s:g} + {SLACK_S:g} s: "
              f"{len(results['stale_releases'])}")
        for m in results["mcap"]:
            print(f"  executor SIGKILLed: {m['path']} {m['size_bytes'] / 1e6:.2f} MB, complete={m['complete']}, "
                  f"recovered {m['messages']} messages on {m['channels']} channels, {m['duration_s']:.1f} s "
                  f"({m['error'] or 'no error'})")
    for line in results["failures"]:
        print(f"{prog}: {line}", file=sys.stderr)
    return 1 if results["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
