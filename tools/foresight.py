"""The ``foresight`` command: one entry point that dispatches to each component's own CLI.

Every sub-command lives in the module that implements it and exposes ``main(argv, prog) -> int``
(the services' ``__main__`` modules, :mod:`tools.router`, :mod:`tools.library`, :mod:`tools.log.cli`,
...), imported only when its command runs; ``foresight <command> --help`` documents all of its
options. ``python -m tools`` runs this dispatcher too.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from shared.arguments import ArgumentParser
from shared.progress import close_interrupted

__all__ = ["COMMANDS", "SUBCOMMANDS", "subcommands", "main"]

# command -> (module with main(argv), one-line description)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("services.demo", "run the whole system on this machine; compare planners (--compare); a PNG of the run"),
    "replayer": ("services.replayer.__main__", "stream recorded human poses over Zenoh"),
    "tracker": ("services.tracker.__main__", "a live person's body keypoints -> human poses and reach markers "
                "(--from FILE: a recording)"),
    "router": ("tools.router", "run a Zenoh router on loopback for local multi-process runs"),
    "library": ("tools.library", "inspect, validate, convert and generate motion libraries"),
    "planner": ("services.planner.__main__", "plan for every goal at once around the predicted occupancy"),
    "executor": ("services.executor.__main__", "simulate the PR2 executing the plans; log the run to MCAP"),
    "log": ("tools.log.cli", "look at a run's MCAP log"),
    "predictor": ("services.predictor.__main__", "recognise the human's motion early; publish predicted occupancy"),
    "train": ("services.predictor.train", "train the prediction model (GMMs, GMR motions, swept volumes)"),
    "eval": ("services.experiments.cli", "the paper's experiments and beyond"),
    "bench": ("services.bench", "benchmark a component"),
    "ros2": ("services.ros2.__main__", "publish the run as ROS 2 topics over rmw_zenoh (RViz, ros2 topic echo)"),
    "view": ("services.view.__main__", "serve a running system live to the Foxglove app (ws://127.0.0.1:8765)"),
    "simrobot": ("services.ros2.robot_sim", "a simulated PR2 arm on ROS 2 (rmw_zenoh) to drive with --robot ros2"),
    "security": ("tools.security", "certificates for mutual TLS and the access control from the wire contract"),
}

SUBCOMMANDS: dict[str, str] = {
    "library": "tools.library:SUBCOMMANDS",
    "log": "tools.log.cli:SUBCOMMANDS",
    "eval": "services.experiments.commands:EXPERIMENTS",
    "bench": "services.bench:BENCHES",
    "security": "tools.security:SUBCOMMANDS",
}
"""Commands with sub-commands -> ``module:table`` of them (name -> help, or name -> (module, help)); light modules,
so that ``foresight --help`` lists every sub-command that exists without importing what runs it."""


def subcommands(command: str) -> dict[str, str]:
    """The sub-commands of ``command`` with their one-line help (empty when it has none)."""
    if command not in SUBCOMMANDS:
        return {}
    module, _, attr = SUBCOMMANDS[command].partition(":")
    table = getattr(importlib.import_module(module), attr)
    return {name: entry if isinstance(entry, str) else entry[-1] if isinstance(entry[-1], str) else entry[0]
            for name, entry in table.items()}


def _parser() -> argparse.ArgumentParser:
    width = max(map(len, COMMANDS))
    lines = []
    for name, (_, desc) in COMMANDS.items():
        lines.append(f"  {name:<{width}}  {desc}")
        subs = subcommands(name)
        sub_width = max(map(len, subs), default=0)
        lines += [f"  {'':<{width}}    {sub:<{sub_width}}  {text}" for sub, text in subs.items()]
    parser = ArgumentParser(
        prog="foresight",
        description="Foresight: plan robot motion around the early-predicted workspace occupancy of a human.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="commands:\n" + "\n".join(lines) + "\n\nRun 'foresight COMMAND --help' for the options of a command.",
        usage="foresight [-h] [-V] COMMAND [ARGS...]",
    )
    # listed (the usage named --version, the options did not): _dispatch answers it before any parsing
    parser.add_argument("-V", "--version", action="store_true", help="print the version and exit")
    return parser


def version() -> str:
    """``foresight X.Y.Z`` (the installed package's version), with the Python it runs on."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        number = installed("foresight")
    except PackageNotFoundError:  # run from a checkout that was never installed (python -m tools)
        number = "(not installed: run from a checkout)"
    return f"foresight {number} (Python {sys.version.split()[0]})"


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``foresight COMMAND ARGS...``; returns the process exit code (130 after Ctrl-C)."""
    try:
        return _dispatch(argv)
    except KeyboardInterrupt as exc:  # Ctrl-C before a command installed its own handler (while importing, ...)
        close_interrupted(exc)
        print("foresight: interrupted", file=sys.stderr)
        return 130


def _dispatch(argv: list[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # the help lists every sub-command, importing each table (and what those modules import): only when shown
    if not argv or argv[0] in ("-h", "--help"):
        _parser().print_help(sys.stdout if argv else sys.stderr)  # no command is an error: its help goes to stderr
        return 0 if argv else 2
    command, rest = argv[0], argv[1:]
    if command in ("-V", "--version"):
        print(version())
        return 0
    if command not in COMMANDS:
        _parser().print_usage(sys.stderr)
        from shared.config_names import closest

        close = closest(command, COMMANDS)  # as a sub-command's misspelt choice (shared.arguments)
        hint = f"{close.removeprefix('; ')} " if close else ""
        print(f"foresight: error: unknown command {command!r} ({hint}choose from {', '.join(COMMANDS)})",
              file=sys.stderr)
        return 2
    from shared.config import ConfigError
    from shared.native_threads import limit_blas_threads

    try:
        limit_blas_threads()
    except ConfigError as exc:
        print(f"foresight: error: {exc}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[command][0])
    try:
        return int(module.main(rest, prog=f"foresight {command}") or 0)
    except BrokenPipeError:  # output piped into e.g. `head`, which exited early
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
