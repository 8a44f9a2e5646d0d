"""``foresight bench NAME``: dispatch to each component's benchmark script (:data:`BENCHES`).

Each benchmark lives beside the code it measures and exposes ``main(argv, prog) -> int``; it is
imported only when asked for.
"""

from __future__ import annotations

import importlib
import sys

__all__ = ["BENCHES", "main"]

BENCHES: dict[str, tuple[str, str]] = {
    "predictor": ("services.predictor.bench", "one pose -> encoded occupancy message (64^3 grid)"),
    "planner": ("services.planner.bench", "one replanning step (STOMP over all goals)"),
    "body": ("services.planner.body_bench", "the planner's body term: the person at rest after a reach, plans with the "
             "term and without; clearance, chosen goal, step time"),
    "faults": ("tools.faults", "a system check (no baseline): kill -9 each service of a moving robot's run: "
               "hold and resume latency, MCAP recovery"),
    "tracker": ("services.tracker.bench", "the live tracker's core on a library's reaches: lag, error, refusals, "
                "time per frame"),
    "tracker-live": ("services.tracker.live_bench", "the tracker as a process behind a router, one reach played at "
                     "30/60/120/240 Hz: how late its poses come"),
    "human": ("services.tracker.demo_bench", "foresight demo in real time, the human from the replayer against the "
              "human through the tracker (keypoints, clean and noisy): pose -> plan p99, keypoints -> pose"),
    "keypoints": ("shared.keypoints.bench", "fit the human model to a frame of body keypoints: live, baseline, batch"),
    "live": ("services.view.bench", "foresight demo in real time without a live view, with --live, with foresight "
             "view (a Foxglove client on each): pose -> plan p99"),
    "separation": ("services.executor.separation_bench", "the executor's separation guard: noisy poses of a person "
                   "in the robot's way, the nearest of the window against the newest pose alone; time per state"),
    "soak": ("tools.soak", "a system check (no baseline): poses at 300 Hz for 60 s: predictor latency and "
             "drops, replanning period, RSS"),
    "codec": ("shared.protocol.bench", "encode and decode of each wire message against bare msgpack: what the "
              "checks cost"),
    "host": ("tools.host_bench", "the same fixed work 300 times in one thread, nothing else of Foresight running: "
             "does this machine stall a busy thread? (the floor under every real-time p99)"),
    "viz": ("shared.foxglove.bench",
            "one occupancy update of the Foxglove scene: SDK protobuf vs the JSON path it replaced"),
}


def main(argv: list[str] | None = None, prog: str = "foresight bench") -> int:
    """Run ``foresight bench NAME ARGS...``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    width = max(map(len, BENCHES))  # 'tracker-live' ran into its text at a fixed 10
    usage = "\n".join(f"  {k:<{width}}  {desc}" for k, (_, desc) in BENCHES.items())
    if not argv or argv[0] in ("-h", "--help"):  # asked for: stdout, 0; no name at all: an error, stderr, 2
        print(f"usage: {prog} {{{','.join(BENCHES)}}} [ARGS...]\n\nbenchmarks:\n{usage}\n\n"
              f"Run '{prog} NAME --help' for a benchmark's options.", file=sys.stdout if argv else sys.stderr)
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in BENCHES:
        print(f"{prog}: error: unknown benchmark {name!r} (choose from {', '.join(BENCHES)})", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(BENCHES[name][0])
    except ModuleNotFoundError as exc:
        print(f"{prog}: error: benchmark {name!r} is not available ({exc})", file=sys.stderr)
        return 2
    return int(module.main(rest, prog=f"{prog} {name}") or 0)


if __name__ == "__main__":
    sys.exit(main())
