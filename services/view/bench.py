"""``foresight bench live``: what watching a run live costs the planning loop.

Runs ``foresight demo --mode realtime`` in rounds of three: without a live view (``none``); with ``--live``,
the executor serving the scene it logs (``live``); and with ``foresight view`` beside it, a process of its own
subscribed over Zenoh (``view``). In the last two a client of Foxglove's WebSocket protocol subscribes to every
scene channel (what the Foxglove app does). The order rotates between rounds so that machine load falls on each
alike. Each run's MCAP gives its pose -> plan latency (p50, p99); printed per run with the messages the client
received, then the median p99 of each variant against ``none``. The target it documents: p99 with a client
connected no more than 5 ms above without. The last line is this machine's stall factor, measured right after
(``foresight bench host``): how much of any p99 the machine alone puts there.

``--slow-client`` adds ``view-slow``: ``foresight view`` with a client that subscribes and then reads nothing (a
stalled app, a dead network path). Each ``view`` run's row also gives the view process's peak memory (VmHWM), so
the two show what a client that stops reading costs the view: the server keeps at most
:data:`shared.foxglove.live.CLIENT_BACKLOG` messages for it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

from services.processes import free_port
from shared.arguments import ArgumentParser
from shared.foxglove.client import FoxgloveClient
from tools.host_bench import stall_line
from tools.log.latency import log_latencies
from tools.system import peak_rss_mb

__all__ = ["main"]

TARGET_MS = 5.0


def _watch(url: str, counts: dict[str, int], done: threading.Event, read: bool = True) -> None:
    """Subscribe to everything at ``url`` and count messages per topic until the server goes or ``done`` is set.

    ``read`` False: subscribe, then read nothing until ``done`` (a client that has stalled).
    """
    try:
        with FoxgloveClient(url, timeout_s=300, keepalive=read) as client:
            client.subscribe()
            if not read:
                counts["nothing read (a stalled client)"] = 0
                done.wait()
                return
            while not client.closed and not done.is_set():
                for r in client.receive(0.5):
                    counts[r.topic] = counts.get(r.topic, 0) + 1
    except Exception as exc:  # noqa: BLE001 - the run goes on; the row says the client failed
        counts[f"client failed: {type(exc).__name__}: {exc}"] = 0


VARIANTS = ("none", "live", "view")
"""No live view; ``foresight demo --live`` (the executor serves); ``foresight view`` beside the demo."""
SLOW = "view-slow"
"""``--slow-client``: ``foresight view`` beside the demo, its client reading nothing."""


def _run(out: Path, variant: str, demo_args: list[str]) -> tuple[dict, dict[str, int], float]:
    """One demo run; returns ``(its JSON summary, messages the client received per topic, the view's peak MB)``."""
    router, port = free_port(), free_port()
    cmd = [sys.executable, "-m", "tools", "demo", "--mode", "realtime", "--no-finish", "--json", "--run-dir", str(out),
           "--port", str(router), *(["--live", str(port)] if variant == "live" else []), *demo_args]
    counts: dict[str, int] = {}
    done = threading.Event()
    watcher = threading.Thread(target=_watch, args=(f"ws://127.0.0.1:{port}", counts, done, variant != SLOW),
                               daemon=True)
    peak = float("nan")
    out.mkdir(parents=True, exist_ok=True)
    view = None
    with (out / "demo.log").open("w") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True, stdin=subprocess.DEVNULL)
        if variant in ("view", SLOW):
            view = subprocess.Popen([sys.executable, "-m", "tools", "view", "--port", str(port), "--connect",
                                     f"tcp/127.0.0.1:{router}"], stdout=err, stderr=err, stdin=subprocess.DEVNULL)
        if variant != "none":
            watcher.start()
        try:
            stdout, _ = proc.communicate(timeout=1200)
            if view is not None:
                peak = peak_rss_mb(view.pid)  # before it is stopped: the run's whole peak
        finally:
            for p in (proc, view):
                if p is not None and p.poll() is None:
                    p.terminate()  # the demo stops its services (bounded), the view its server
                    p.wait(60)
    done.set()
    if variant != "none":
        watcher.join(10)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with status {proc.returncode}; see {out / 'demo.log'}")
    return json.loads(stdout), counts, peak


def main(argv: list[str] | None = None, prog: str = "foresight bench live") -> int:
    """Run the benchmark; returns the exit status (0: ran; the target's verdict is printed)."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds of one run per variant (none, live, view)")
    parser.add_argument("--out", default="runs/bench-live", help="the runs' directories")
    parser.add_argument("--slow-client", action="store_true", help=f"also {SLOW}: foresight view with a client that "
                        "reads nothing; the view's peak memory against view's")
    parser.add_argument("demo_args", nargs=argparse.REMAINDER, help="after --: more `foresight demo` options")
    args = parser.parse_args(argv)
    demo_args = [a for a in args.demo_args if a != "--"]
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")
    variants = (*VARIANTS, SLOW) if args.slow_client else VARIANTS
    rows: dict[str, list[float]] = {v: [] for v in variants}
    peaks: dict[str, list[float]] = {v: [] for v in variants}
    print(f"{'run':<12}{'pose->plan p50':>15}{'p99 ms':>9}{'view MB':>9}  client received")
    for i in range(args.rounds):
        k = i % len(variants)
        for variant in variants[k:] + variants[:k]:
            name = f"{variant}-{i}"
            t0 = time.monotonic()
            summary, counts, peak = _run(Path(args.out) / name, variant, demo_args)
            stat = log_latencies(summary["mcap_path"])["pose_to_plan"]
            rows[variant].append(stat.p99)
            peaks[variant].append(peak)
            got = ", ".join(f"{t} {n}" for t, n in sorted(counts.items())) if variant != "none" else "-"
            print(f"{name:<12}{stat.p50:>15.1f}{stat.p99:>9.1f}{peak:>9.0f}  {got}  ({time.monotonic() - t0:.0f} s)",
                  flush=True)
    base = statistics.median(rows["none"])
    print(f"median pose -> plan p99 without a live view: {base:.1f} ms")
    for variant, what in (("live", "foresight demo --live (the executor serves)"),
                          ("view", "foresight view beside the demo"), (SLOW, "foresight view, its client stalled")):
        if variant not in rows:
            continue
        med = statistics.median(rows[variant])
        print(f"  {what}, a client connected: {med:.1f} ms, {med - base:+.1f} ms "
              f"(target <= +{TARGET_MS:g} ms: {'met' if med - base <= TARGET_MS else 'missed'})")
    if args.slow_client:
        read, stalled = statistics.median(peaks["view"]), statistics.median(peaks[SLOW])
        print(f"view's peak memory, median: {read:.0f} MB with a client reading, {stalled:.0f} MB with one that reads "
              f"nothing ({stalled / read:.2f}x)")
    print(stall_line())
    return 0


if __name__ == "__main__":
    sys.exit(main())
