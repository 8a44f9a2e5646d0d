"""``foresight bench human``: what the tracker in the loop costs the real-time planning loop.

Runs ``foresight demo --mode realtime`` in rounds of three: the human from the replayer (``replayer``, the
baseline), the same demonstration as body keypoints through ``foresight tracker --from`` (``keypoints``), and the
same with 2 cm of Gaussian noise per axis (``noisy``). The order rotates between rounds so that machine load falls
on each alike. Each run's MCAP gives pose -> plan (p50, p99) and, with the tracker, keypoints -> pose and
keypoints -> plan; printed per run, then the median p99 of each variant against ``replayer``. The target it
documents: pose -> plan p99 with the tracker no more than 10 ms above the replayer's. The last line is this
machine's stall factor, measured right after (``foresight bench host``): how much of any p99 the machine alone
puts there.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

from services.processes import free_port
from shared.arguments import ArgumentParser
from shared.runtime import cli_errors
from tools.host_bench import stall_line
from tools.log.latency import log_latencies

__all__ = ["main", "VARIANTS", "TARGET_MS"]

TARGET_MS = 10.0

VARIANTS: dict[str, list[str]] = {
    "replayer": [],
    "keypoints": ["--human", "keypoints"],
    "noisy": ["--human", "keypoints", "--keypoint-noise-m", "0.02"],
}
"""Each variant's ``foresight demo`` options."""


def _run(out: Path, variant: str, demo_args: list[str]) -> dict:
    """One demo run; returns its JSON summary."""
    cmd = [sys.executable, "-m", "tools", "demo", "--mode", "realtime", "--no-finish", "--json", "--run-dir", str(out),
           "--port", str(free_port()), *VARIANTS[variant], *demo_args]  # --no-finish: the run's 10 s, as measured
    out.mkdir(parents=True, exist_ok=True)
    with (out / "demo.log").open("w") as err:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=err, text=True, stdin=subprocess.DEVNULL,
                              timeout=1200)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with status {proc.returncode}; see {out / 'demo.log'}")
    return json.loads(proc.stdout)


def main(argv: list[str] | None = None, prog: str = "foresight bench human") -> int:
    """Run the benchmark; returns the exit status (0: ran; the target's verdict is printed)."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds of one run per variant")
    parser.add_argument("--out", default="runs/bench-human", help="the runs' directories")
    parser.add_argument("demo_args", nargs=argparse.REMAINDER, help="after --: more `foresight demo` options")
    args = parser.parse_args(argv)
    if args.rounds < 1:  # before any run: a round is three demo runs of a minute or more
        parser.error(f"--rounds must be at least 1, got {args.rounds}")
    with cli_errors(prog):
        return _rounds(args)


def _rounds(args: argparse.Namespace) -> int:
    """The runs of :func:`main`'s checked options, their table and the summary."""
    demo_args = [a for a in args.demo_args if a != "--"]
    names = list(VARIANTS)
    rows: dict[str, list[float]] = {v: [] for v in names}
    print(f"{'run':<13}{'pose->plan p50':>15}{'p99 ms':>9}{'keypoints->pose p50':>21}{'p99':>8}"
          f"{'keypoints->plan p50':>21}{'p99':>8}")
    for i in range(args.rounds):
        for variant in names[i % 3:] + names[:i % 3]:
            name = f"{variant}-{i}"
            t0 = time.monotonic()
            summary = _run(Path(args.out) / name, variant, demo_args)
            stats = log_latencies(summary["mcap_path"])
            plan = stats["pose_to_plan"]
            rows[variant].append(plan.p99)
            kp = [stats[k] for k in ("keypoints_to_pose", "keypoints_to_plan") if k in stats]
            tail = "".join(f"{s.p50:>21.1f}{s.p99:>8.1f}" for s in kp) if kp else f"{'-':>21}{'':>8}{'-':>21}"
            print(f"{name:<13}{plan.p50:>15.1f}{plan.p99:>9.1f}{tail}  ({time.monotonic() - t0:.0f} s)", flush=True)
    base = statistics.median(rows["replayer"])
    print(f"median pose -> plan p99 with the replayer: {base:.1f} ms")
    for variant, what in (("keypoints", "the tracker (clean keypoints)"), ("noisy", "the tracker (2 cm noise)")):
        med = statistics.median(rows[variant])
        print(f"  {what}: {med:.1f} ms, {med - base:+.1f} ms (target <= +{TARGET_MS:g} ms: "
              f"{'met' if med - base <= TARGET_MS else 'missed'})")
    print(stall_line())
    return 0


if __name__ == "__main__":
    sys.exit(main())
