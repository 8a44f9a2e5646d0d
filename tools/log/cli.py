"""``foresight log``: look at a run's MCAP log without Foxglove.

* ``foresight log info FILE [--json]``: channels, schemas and message counts (:mod:`tools.log.info`);
* ``foresight log render FILE --step N --out PNG`` (or ``--all --out DIR``): draw replanning steps, a real-time
  run's plans (:mod:`tools.log.render`);
* ``foresight log latency FILE [--json] [--slowest N]``: pose -> occupancy -> plan latencies, and the N plans
  with the longest pose -> plan, slowest first (:mod:`tools.log.latency`);
* ``foresight log compress IN OUT``: the same log with compressed chunks, read back identical
  (:mod:`tools.log.compress`);
* ``foresight log snapshot FILE [--at SECONDS] [--out PNG]``: the logged 3D scene (Foxglove's channels) at a
  moment of the run (:mod:`tools.log.snapshot`).

The log is read with :func:`shared.recording.reader.read_log` (record by record: a truncated file is
read up to its last complete chunk); ``snapshot`` reads only the scene channels
(:func:`shared.foxglove.decode.read_scene`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

from services.demo_dirs import compare_log
from shared import strict_json
from shared.arguments import ArgumentParser
from shared.atomic_file import ready_to_write
from shared.recording.reader import LogFile, log_path, read_log
from shared.runtime import UserError, cli_errors

from ..png import check_png
from .compress import compress_log
from .info import format_info, info_dict
from .latency import PlanSample, format_latencies, format_slowest, log_latencies, slowest_plans
from .render import render_step
from .steps import scene_of, step_views

__all__ = ["main", "SUBCOMMANDS"]

SUBCOMMANDS: dict[str, str] = {
    "info": "channels, schemas and message counts of an MCAP log",
    "render": "draw replanning step(s) to PNG",
    "latency": "pose -> occupancy -> plan latencies and the replanning period (p50, p99)",
    "compress": "rewrite a log with compressed chunks; read both back, compare them",
    "table": "the run's step table (goal per step, costs), switch step, goal reached, as foresight demo prints it",
    "snapshot": "draw the logged 3D scene (Foxglove's channels) at a time to PNG",
}
"""The sub-commands of ``foresight log`` with one line each (``foresight --help`` lists them)."""

_FILE_HELP = "MCAP file, or a run's directory (its log; a demo --compare run's: the prediction run's)"


def _main_info(args: argparse.Namespace) -> int:
    """One log's summary; a directory's: every log under it (``--json``: a list), as after ``demo --compare``."""
    path = Path(args.file)
    logs = sorted(f for f in path.rglob("*.mcap") if f.is_file()) if path.is_dir() else []
    if not logs:  # a file, or a directory with none: read_log reads it or names the problem
        lf = read_log(path)
        print(strict_json.dumps(info_dict(lf), indent=2) if args.json else format_info(lf))
        return 0
    shown: list[object] = []
    failed = 0
    for f in logs:  # one unreadable log (empty, not MCAP) is named in its place; the others are still described
        try:
            lf = read_log(f)
            shown.append(info_dict(lf) if args.json else format_info(lf))
        except UserError as exc:
            failed += 1
            said = str(exc) if str(exc).startswith(str(f)) else f"{f}: {exc}"  # the path once, not "f: f: ..."
            shown.append({"file": str(f), "unreadable": str(exc)} if args.json else f"file: {said}")
    print(strict_json.dumps(shown, indent=2) if args.json else "\n\n".join(str(x) for x in shown))
    return 2 if failed == len(logs) else 1 if failed else 0  # one unreadable of several: not a success either


def _main_render(args: argparse.Namespace, prog: str) -> int:
    if args.all and args.step is not None:  # --step was ignored without a word, and every step drawn
        raise UserError("give --step N or --all, not both")
    if not args.all:
        check_png(str(args.out), "--out", make_folder=False)  # matplotlib would write NAME.png where we print NAME
    elif args.out.exists() and not args.out.is_dir():  # it failed with "File exists" after reading the log
        raise UserError(f"--out {args.out}: a file; with --all, --out is the directory of the PNGs")
    else:
        _check_out(args.out, directory=True)  # before the log is read; nothing made until the PNGs are drawn
    wanted = {"foresight.Plan", "foresight.OccupancyGrid", "foresight.HumanPose", "foresight.RobotState"}
    lf = read_log(args.file, keep=lambda ch: ch.schema_name in wanted and ch.message_encoding == "msgpack")
    views = step_views(lf)
    if not views:
        raise UserError(_with_state(f"{args.file}: no Plan messages in the log, nothing to render", lf))
    scene = scene_of(lf)
    # a real-time run's plans are numbered by their place in the log (as `log table` numbers them), not steps
    word = "plan" if any(v.number is not None for v in views.values()) else "step"
    if args.all:
        steps = sorted(views)
    else:
        if args.step is None:
            raise UserError("give --step N or --all")
        if args.step not in views:
            what = f"plan {args.step}" if word == "plan" else f"plan for step {args.step}"
            raise UserError(_with_state(f"{args.file}: no {what} ({word}s {_ranges(sorted(views))})", lf))
        steps = [args.step]
    import torch

    from shared.robot import PR2

    robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    _make_for(args.out, directory=args.all)
    for n in steps:
        out = Path(args.out) / f"{word}_{n:03d}.png" if args.all else Path(args.out)
        render_step(views[n], scene, out, robot=robot, min_probability=args.min_probability)
        print(out)
    _note_truncated(lf)
    return 0


def _ranges(numbers: list[int]) -> str:
    """Sorted numbers as runs: ``0..3, 5, 7..9`` (a real-time run's adopted plans have gaps)."""
    runs: list[list[int]] = []
    for n in numbers:
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    return ", ".join(f"{a}..{b}" if b > a else f"{a}" for a, b in runs)


def _with_state(message: str, lf: LogFile) -> str:
    """An error about what a log lacks, with the log's state when it is not complete: the damage may be why."""
    return message if lf.complete else f"{message} (the log is {lf.state})"


def _check_out(out: Path, directory: bool = False) -> None:
    """Refuse, before the log is read, an output path with a file where a directory is needed; nothing is made."""
    for above in ([out] if directory else []) + list(out.parents):
        if above.exists():
            if not above.is_dir():
                raise UserError(f"{above}: a file is in the way (a directory is needed there)")
            return


def _make_for(out: Path, directory: bool = False) -> None:
    """Make the directories an output goes in, just before it is written, and say so (one line on stderr).

    They were made before the log was read, and left behind when it failed (a review).
    """
    need = out if directory else out.parent
    missing = not need.exists()
    ready_to_write(out, directory=directory)
    if missing:
        print(f"foresight log: note: made the directory {need}", file=sys.stderr)


def _note_truncated(lf: LogFile) -> None:
    """Say on stderr that a log is not complete: what the tools print of it stops where the file does."""
    if lf.summary_damaged:
        print(f"foresight log: note: {lf.path} is {lf.state}: it was read in file order, not through its index",
              file=sys.stderr)
    elif lf.damage:
        print(f"foresight log: note: {lf.path} is {lf.state}: what follows lacks what the damage took",
              file=sys.stderr)
    elif not lf.complete:
        print(f"foresight log: note: {lf.path} is {lf.state}: what follows covers the run up to its last whole "
              "chunk only", file=sys.stderr)


def _main_table(args: argparse.Namespace) -> int:
    from .table import WANTED, run_summary, table_lines

    lf = read_log(args.file, keep=lambda ch: ch.schema_name in WANTED and ch.message_encoding == "msgpack")
    summary = run_summary(lf)
    if not summary.steps:
        raise UserError(_with_state(f"{args.file}: no plans logged", lf))
    _note_truncated(lf)
    print(strict_json.dumps({**summary.to_json(), "complete": lf.complete, "error": lf.error}) if args.json
          else "\n".join(table_lines(summary)))
    return 0


def _main_snapshot(args: argparse.Namespace) -> int:
    from .snapshot import draw_snapshot, scene_at

    file = log_path(args.file)  # a run's directory: its log (the picture beside it, named for it)
    if args.out is not None:
        check_png(str(args.out), "--out", make_folder=False)
    out = Path(args.out) if args.out is not None else file.with_name(f"{file.stem}-snapshot.png")
    _check_out(out)  # before the scene is read: a file in the way of its directory, named; nothing made yet
    state = scene_at(file, args.at)
    if args.at is not None and args.at > state.t_s + 1e-6:  # it drew the end without a word
        print(f"foresight log: note: --at {args.at:g} s is past the end of the scene ({state.t_s:.3f} s of "
              "recording; a lock-step run records its simulated steps faster): drawing its last state",
              file=sys.stderr)
    _make_for(out)
    draw_snapshot(state, out, title=file.name)
    _note_truncated(read_log(file, keep=lambda ch: False))  # whether the scene reader stopped at a damaged chunk
    print(f"wrote {out} ({state.summary()})")
    return 0


def _main_latency(args: argparse.Namespace) -> int:
    if args.slowest < 0:
        raise UserError(f"--slowest: must be 0 or more plans, got {args.slowest}")
    try:
        read: list[LogFile] = []
        samples: list[PlanSample] = []
        stats = log_latencies(args.file, read, samples)
    except ValueError as exc:
        raise UserError(_with_state(str(exc), read[0]) if read else str(exc)) from exc
    _note_truncated(read[0])
    slow = slowest_plans(samples, args.slowest)
    if args.json:  # strict JSON: a series without samples has null statistics, not NaN
        extra = {"slowest": [dataclasses.asdict(s) | {"not_planning_ms": s.not_planning_ms} for s in slow]
                 } if args.slowest else {}
        print(strict_json.dumps({**{k: dataclasses.asdict(v) for k, v in stats.items()}, **extra,
                                 "complete": read[0].complete, "error": read[0].error}))
    else:
        print(format_latencies(stats))
        if args.slowest:
            print(format_slowest(slow))
    return 0


def main(argv: list[str] | None = None, prog: str = "foresight log") -> int:
    """``foresight log info|render|latency|compress|table|snapshot``; returns the exit status."""
    parser = ArgumentParser(prog=prog, description="Look at a run's MCAP log without Foxglove: 'info' "
                                     "lists channels, schemas and message counts; 'render' draws replanning steps "
                                     "to PNG (table, cups, human, predicted occupancy, robot spheres, candidate "
                                     "end-effector paths); 'latency' measures pose -> occupancy -> plan; 'compress' "
                                     "rewrites a log with compressed chunks; 'snapshot' draws the logged 3D "
                                     "scene (Foxglove's channels) at a moment of the run.")
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="{" + ",".join(SUBCOMMANDS) + "}")
    pi = sub.add_parser("info", help=SUBCOMMANDS["info"])
    pi.add_argument("file", help="MCAP file, or a directory: every log under it (a demo --compare run's)")
    pi.add_argument("--json", action="store_true", help="print one JSON object")
    pr = sub.add_parser("render", help=SUBCOMMANDS["render"])
    pr.add_argument("file", help=_FILE_HELP)
    pr.add_argument("--step", type=int, default=None, metavar="N",
                    help="replanning step (Plan.step) to draw; a real-time run's: plan N, numbered as "
                    "'foresight log table' numbers them")
    pr.add_argument("--all", action="store_true", help="draw every step (step_NNN.png; a real-time run's plans: "
                    "plan_NNN.png); --out is then a directory")
    pr.add_argument("--out", required=True, type=Path, help="PNG path (or directory with --all)")
    pr.add_argument("--min-probability", type=float, default=0.05, help="hide voxels below this probability")
    pl = sub.add_parser("latency", help=SUBCOMMANDS["latency"])
    pl.add_argument("file", help=_FILE_HELP)
    pl.add_argument("--json", action="store_true", help="print one JSON object")
    pl.add_argument("--slowest", type=int, default=0, metavar="N",
                    help="also list the N plans with the longest pose -> plan, each split into its planning time and "
                    "the rest (the wait for the step before it, and travel): is a tail slow steps or late starts?")
    pc = sub.add_parser("compress", help=SUBCOMMANDS["compress"])
    pc.add_argument("file", help=_FILE_HELP)
    pc.add_argument("out", type=Path, help="the new MCAP file")
    pc.add_argument("--compression", default="zstd", choices=("zstd", "lz4", "none"), help="chunk compression")
    pt = sub.add_parser("table", help=SUBCOMMANDS["table"])
    pt.add_argument("file", help=_FILE_HELP)
    pt.add_argument("--json", action="store_true", help="print one JSON object (the demo's --json keys)")
    ps = sub.add_parser("snapshot", help=SUBCOMMANDS["snapshot"])
    ps.add_argument("file", help=_FILE_HELP)
    ps.add_argument("--at", type=float, default=None, metavar="SECONDS",
                    help="seconds of recording (log time, wall clock) from the first scene record; a lock-step run "
                         "records its simulated steps faster than they are simulated (default: the last plan)")
    ps.add_argument("--out", default=None, metavar="PNG", type=Path,
                    help="PNG path (default: FILE's stem + '-snapshot.png' next to it)")
    args = parser.parse_args(argv)
    with cli_errors(f"{prog} {args.cmd}"):  # 'foresight log render: error: ...', not 'foresight log
        if args.cmd != "info" and (main_log := compare_log(Path(args.file))) is not None:
            print(f"foresight log: note: {args.file} is a demo --compare run: its prediction run's log, {main_log} "
                  "(the other planners': their own directories under it)", file=sys.stderr)
            args.file = str(main_log)
        if args.cmd == "table":
            return _main_table(args)
        if args.cmd == "compress":
            _check_out(args.out)
            missing = not args.out.parent.exists()
            result = compress_log(args.file, args.out, args.compression)
            if missing:  # made by its atomic write, once the input was found to be a log
                print(f"foresight log: note: made the directory {args.out.parent}", file=sys.stderr)
            print(result.line(log_path(args.file), Path(args.out)))
            return 0 if result.ok else 1  # a copy that lacks part of a damaged input is no success
        if args.cmd == "info":
            return _main_info(args)
        if args.cmd == "latency":
            return _main_latency(args)
        if args.cmd == "snapshot":
            return _main_snapshot(args)
        if not (0.0 <= args.min_probability <= 1.0) or math.isnan(args.min_probability):
            raise UserError(f"--min-probability must be in [0, 1], got {args.min_probability}")
        return _main_render(args, prog)
    return 2  # pragma: no cover


if __name__ == "__main__":
    sys.exit(main())
