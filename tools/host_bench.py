"""``foresight bench host``: does this machine stall a busy thread? The floor under every real-time tail.

A real-time run's p99 (pose -> plan, ``foresight log latency``) is a planning step that took longer than most. On
some machines the code has nothing to do with it: the machine stops a busy thread now and then (a virtual machine
whose host schedules its virtual CPUs, a laptop's power states, a noisy neighbour). This benchmark times the same
fixed work again and again in one thread, with nothing of Foresight's running, and prints how the slowest runs
compare with the median:

* ``torch``: ``--products`` products of two 256 x 256 matrices, each through ``tanh`` (torch, ``--threads``
  threads, as a planning step's kernels run);
* ``python``: a pure-Python loop of ``--loop`` additions (as the services' own code runs).

The ratio p99 / median is the host's stall factor: a planning step of median ``m`` ms will see about ``m x`` that
ratio at its p99 however fast the code is (docs/planner.md, "The machine, not the code"). On Linux the CPU time the
host took from this machine while it ran (``steal``, ``/proc/stat``) is printed too; a virtual machine's host may
stall it without counting it there.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.runtime import UserError, cli_errors

from .cpus import usable_cpus

__all__ = ["stall_stats", "time_work", "steal_share", "run_bench", "format_bench", "stall_line", "main", "MAX_THREADS"]

MAX_THREADS = 1024
"""The most ``--threads`` (torch segfaulted at 100000000 and raised a traceback at 99999999999)."""


def stall_stats(ms: list[float]) -> dict[str, Any]:
    """Median, p99, max (ms), their ratios to the median and the runs slower than twice the median.

    Args:
        ms: One duration per run (ms), at least one.
    """
    a = np.asarray(ms, dtype=np.float64)
    if a.size == 0 or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"durations must be finite and positive, got {len(a)} of them: {a[:5].tolist()}...")
    p50, p99 = float(np.percentile(a, 50)), float(np.percentile(a, 99))
    return {"runs": int(a.size), "p50_ms": p50, "p99_ms": p99, "max_ms": float(a.max()), "p99_over_p50": p99 / p50,
            "max_over_p50": float(a.max()) / p50, "over_2x": int((a > 2 * p50).sum())}


def time_work(work: Callable[[], object], repeats: int,
              clock: Callable[[], float] = time.perf_counter) -> list[float]:
    """Milliseconds of each of ``repeats`` calls of ``work`` (after one untimed call)."""
    work()
    out = []
    for _ in range(repeats):
        t0 = clock()
        work()
        out.append((clock() - t0) * 1e3)
    return out


def _cpu_times() -> list[int] | None:
    """The machine's CPU time counters (``/proc/stat``'s ``cpu`` line), None where there is none."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
    except OSError:
        return None
    return [int(v) for v in fields[1:]] if fields and fields[0] == "cpu" else None


def steal_share(before: list[int] | None, after: list[int] | None) -> float | None:
    """The share of CPU time the host took (``steal``, the 8th counter) between two :func:`_cpu_times` readings."""
    if before is None or after is None or len(before) < 8 or len(after) < 8:
        return None
    delta = [b - a for a, b in zip(before, after, strict=False)]
    total = sum(delta[:8])
    return delta[7] / total if total > 0 else 0.0


def _torch_work(products: int, threads: int) -> Callable[[], object]:
    import torch

    torch.set_num_threads(threads)
    a = torch.randn(256, 256, generator=torch.Generator().manual_seed(0))

    def work() -> object:
        x = a
        for _ in range(products):
            x = torch.tanh(x @ a)
        return x

    return work


def _python_work(loop: int) -> Callable[[], object]:
    def work() -> object:
        s = 0
        for i in range(loop):
            s += i
        return s

    return work


def run_bench(repeats: int = 300, products: int = 60, loop: int = 300_000, threads: int = 1,
              say: Callable[[str], None] = lambda _s: None) -> dict[str, Any]:
    """Time both workloads ``repeats`` times each (``say`` is told which, as it starts); the report dict."""
    out: dict[str, Any] = {"repeats": repeats, "threads": threads, "cpus": usable_cpus(), "cpu_count": os.cpu_count(),
                           "load_avg_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}
    before = _cpu_times()
    for name, work in (("torch", _torch_work(products, threads)), ("python", _python_work(loop))):
        say(f"{name}: {repeats} runs ...")
        out[name] = stall_stats(time_work(work, repeats))
    out["steal_share"] = steal_share(before, _cpu_times())
    return out


def format_bench(r: dict[str, Any]) -> str:
    """The report as a table and a one-line reading of it."""
    load = r.get("load_avg_1min")
    count = r.get("cpu_count")
    cpus = ("CPUs not known" if r.get("cpus") is None else f"{r['cpus']} usable CPUs"
            + (f" of {count}" if count is not None and count != r["cpus"] else ""))
    threads = r.get("threads", 1)  # --threads 3 read "in one thread": the torch work ran on 3
    how = " in one thread" if threads == 1 else f", torch on {threads} threads and python on one"
    lines = [f"the same work {r['repeats']} times{how} ({cpus}, "
             + ("load not known here" if load is None else f"load {load:.2f}") + "):",
             f"{'work':<8}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}{'p99/p50':>9}{'max/p50':>9}{'> 2x p50':>10}"]
    for name in ("torch", "python"):
        s = r[name]
        lines.append(f"{name:<8}{s['p50_ms']:>9.1f}{s['p99_ms']:>9.1f}{s['max_ms']:>9.1f}{s['p99_over_p50']:>9.2f}"
                     f"{s['max_over_p50']:>9.2f}{s['over_2x']:>10}")
    steal = r.get("steal_share")
    lines.append("steal (CPU time the host took): "
                 + ("not available here" if steal is None else f"{100 * steal:.2f} %"))
    worst = max(r["torch"]["p99_over_p50"], r["python"]["p99_over_p50"])
    lines.append(f"stall factor {worst:.2f}: a real-time step of median m ms will see about {worst:.1f} m at its p99 "
                 "on this machine however fast the code is" + (" (a quiet machine: under 1.5)" if worst < 1.5 else ""))
    return "\n".join(lines)


def stall_line(repeats: int = 100, products: int = 60) -> str:
    """One line for a real-time benchmark's end: this machine's stall factor, measured now (the torch work only).

    A p99 of those benchmarks compares runs on one machine; this says how much of any p99 the machine alone puts
    there (about 3 s of work at the defaults).
    """
    s = stall_stats(time_work(_torch_work(products, 1), repeats))
    quiet = "a quiet machine" if s["p99_over_p50"] < 1.5 else "not a quiet machine"
    return (f"this machine's stall factor, measured now ({repeats} runs of `foresight bench host`'s torch work): "
            f"{s['p99_over_p50']:.2f} ({quiet}: under 1.5 is); a step of median m ms is about that times m at its "
            "p99 whatever the code")


def main(argv: list[str] | None = None, prog: str = "foresight bench host") -> int:
    """``foresight bench host``; returns the exit status."""
    ap = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=300, help="runs of each workload")
    ap.add_argument("--products", type=int, default=60, help="matrix products per torch run")
    ap.add_argument("--loop", type=int, default=300_000, help="additions per Python run")
    ap.add_argument("--threads", type=int, default=1,
                    help=f"torch threads, 1 to {MAX_THREADS} (the planner's default: 1)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args(argv)
    with cli_errors(prog):
        for name in ("repeats", "products", "loop", "threads"):
            if getattr(args, name) < 1:
                raise UserError(f"--{name}: must be 1 or more, got {getattr(args, name)}")
        if args.threads > MAX_THREADS:
            raise UserError(f"--threads: must be 1 to {MAX_THREADS}, got {args.threads}")
        say = (lambda _s: None) if args.json else (lambda s: print(s, file=sys.stderr, flush=True))
        r = run_bench(args.repeats, args.products, args.loop, args.threads, say)
        print(strict_json.dumps(r) if args.json else format_bench(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
