"""``foresight log``: look at a run's MCAP log without Foxglove.

* ``foresight log info FILE [--json]``: channels, schemas and message counts (:mod:`tools.log.info`);
* ``foresight log render FILE --step N --out PNG`` (or ``--all --out DIR``): draw replanning steps
  (:mod:`tools.log.render`);
* ``foresight log latency FILE [--json]``: pose -> occupancy -> plan latencies (:mod:`tools.log.latency`);
* ``foresight log compress IN OUT``: the same log with compressed chunks, read back identical
  (:mod:`tools.log.compress`).

The log is read with :func:`shared.recording.reader.read_log` (record by record: a truncated file is
read up to its last complete chunk).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path

from shared.recording.reader import read_log
from shared.runtime import UserError, cli_errors

from .compress import compress_log
from .info import format_info, info_dict
from .latency import format_latencies, run_latencies
from .render import render_step
from .steps import scene_of, step_views

__all__ = ["main", "SUBCOMMANDS"]

SUBCOMMANDS: dict[str, str] = {
    "info": "channels, schemas and message counts of an MCAP log",
    "render": "draw replanning step(s) to PNG",
    "latency": "pose -> occupancy -> plan latencies and the replanning period (p50, p99)",
    "compress": "rewrite a log with compressed chunks; read both back, compare them",
    "table": "the run's step table (goal per step, costs), switch step, goal reached, as foresight demo prints it",
}
"""The sub-commands of ``foresight log`` with one line each (``foresight --help`` lists them)."""


def _main_info(args: argparse.Namespace) -> int:
    lf = read_log(args.file)
    if args.json:
        print(json.dumps(info_dict(lf), indent=2))
    else:
        print(format_info(lf))
    return 0


def _main_render(args: argparse.Namespace, prog: str) -> int:
    wanted = {"foresight.Plan", "foresight.OccupancyGrid", "foresight.HumanPose", "foresight.RobotState"}
    lf = read_log(args.file, keep=lambda ch: ch.schema_name in wanted and ch.message_encoding == "msgpack")
    views = step_views(lf)
    if not views:
        raise UserError(f"{args.file}: no Plan messages in the log, nothing to render")
    scene = scene_of(lf)
    if args.all:
        steps = sorted(views)
    else:
        if args.step is None:
            raise UserError("give --step N or --all")
        if args.step not in views:
            raise UserError(f"{args.file}: no plan for step {args.step} (steps {min(views)}..{max(views)})")
        steps = [args.step]
    import torch

    from shared.robot import PR2

    robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    for n in steps:
        out = Path(args.out) / f"step_{n:03d}.png" if args.all else Path(args.out)
        render_step(views[n], scene, out, robot=robot, min_probability=args.min_probability)
        print(out)
    if not lf.complete:
        print(f"{prog}: note: {args.file} is truncated ({lf.error or 'no footer'})", file=sys.stderr)
    return 0


def _main_table(args: argparse.Namespace) -> int:
    from .table import WANTED, run_summary, table_lines

    lf = read_log(args.file, keep=lambda ch: ch.schema_name in WANTED and ch.message_encoding == "msgpack")
    summary = run_summary(lf)
    if not summary.steps:
        raise UserError(f"{args.file}: no plans logged")
    print(json.dumps(summary.to_json()) if args.json else "\n".join(table_lines(summary)))
    return 0


def _main_latency(args: argparse.Namespace) -> int:
    wanted = {"foresight.Plan", "foresight.OccupancyGrid", "foresight.HumanPose", "foresight.DemoMarker"}
    lf = read_log(args.file, keep=lambda ch: ch.schema_name in wanted and ch.message_encoding == "msgpack")
    topics = {}
    for ch in lf.channels.values():
        for key, schema in (("pose", "foresight.HumanPose"), ("occupancy", "foresight.OccupancyGrid"),
                            ("plan", "foresight.Plan"), ("demo", "foresight.DemoMarker")):
            if ch.schema_name == schema and ch.message_encoding == "msgpack":
                topics[key] = ch.topic
    if not {"pose", "occupancy", "plan"} <= set(topics):
        raise UserError(f"{args.file}: needs HumanPose, OccupancyGrid and Plan channels, found {sorted(topics)}")
    stats = run_latencies(lf.messages, topics)
    if args.json:
        print(json.dumps({k: dataclasses.asdict(v) for k, v in stats.items()}))
    else:
        print(format_latencies(stats))
    return 0


def main(argv: list[str] | None = None, prog: str = "foresight log") -> int:
    """``foresight log info|render|latency|compress|table``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description="Look at a run's MCAP log without Foxglove: 'info' "
                                     "lists channels, schemas and message counts; 'render' draws replanning steps "
                                     "to PNG (table, cups, human, predicted occupancy, robot spheres, candidate "
                                     "end-effector paths); 'latency' measures pose -> occupancy -> plan; 'compress' "
                                     "rewrites a log with compressed chunks.")
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="{" + ",".join(SUBCOMMANDS) + "}")
    pi = sub.add_parser("info", help=SUBCOMMANDS["info"])
    pi.add_argument("file", help="MCAP file")
    pi.add_argument("--json", action="store_true", help="print one JSON object")
    pr = sub.add_parser("render", help=SUBCOMMANDS["render"])
    pr.add_argument("file", help="MCAP file")
    pr.add_argument("--step", type=int, default=None, help="replanning step (Plan.step) to draw")
    pr.add_argument("--all", action="store_true", help="draw every step; --out is then a directory")
    pr.add_argument("--out", required=True, help="PNG path (or directory with --all)")
    pr.add_argument("--min-probability", type=float, default=0.05, help="hide voxels below this probability")
    pl = sub.add_parser("latency", help=SUBCOMMANDS["latency"])
    pl.add_argument("file", help="MCAP file")
    pl.add_argument("--json", action="store_true", help="print one JSON object")
    pc = sub.add_parser("compress", help=SUBCOMMANDS["compress"])
    pc.add_argument("file", help="MCAP file")
    pc.add_argument("out", help="the new MCAP file")
    pc.add_argument("--compression", default="zstd", choices=("zstd", "lz4", "none"), help="chunk compression")
    pt = sub.add_parser("table", help=SUBCOMMANDS["table"])
    pt.add_argument("file", help="MCAP file")
    pt.add_argument("--json", action="store_true", help="print one JSON object (the demo's --json keys)")
    args = parser.parse_args(argv)
    with cli_errors(prog):
        if args.cmd == "table":
            return _main_table(args)
        if args.cmd == "compress":
            result = compress_log(args.file, args.out, args.compression)
            print(result.line(Path(args.file), Path(args.out)))
            return 0 if result.identical else 1
        if args.cmd == "info":
            return _main_info(args)
        if args.cmd == "latency":
            return _main_latency(args)
        if not (0.0 <= args.min_probability <= 1.0) or math.isnan(args.min_probability):
            raise UserError(f"--min-probability must be in [0, 1], got {args.min_probability}")
        return _main_render(args, prog)
    return 2  # pragma: no cover


if __name__ == "__main__":
    sys.exit(main())
