"""``foresight library``: inspect, validate and convert human-motion libraries.

Sub-commands (each is one ``_cmd_<name>`` function registered in :data:`SUBCOMMANDS`; adding one
means writing its ``add_arguments``/``run`` pair and one entry there):

- ``info PATH``: features (and their mapping to the human model), classes, valid demonstrations per
  class, sample counts, issues.
- ``validate PATH``: print every malformed demonstration; exit status 1 if there is any.
- ``convert PATH --out FILE.npz``: write the native npz (valid demonstrations and the issue list).
- ``generate --classes 8 --demos 25 --seed 0 --out PATH``: a synthetic library (shared/synthetic.py).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from shared.feature_sets import describe_features
from shared.library import LibraryError, MotionLibrary, load_library, save_library
from shared.runtime import cli_errors
from shared.synthetic import add_generate_arguments, run_generate

__all__ = ["main", "SUBCOMMANDS", "format_info"]


def format_info(lib: MotionLibrary) -> str:
    """Human-readable summary: the features, one line per class, then the issues."""
    lines = [f"library: {lib.source}", f"classes: {lib.n_classes}, valid demonstrations: {len(lib.demos)}, "
             f"issues: {len(lib.issues)}, features: {describe_features(lib.feature_names)}"]
    width = max((len(n) for n in lib.class_names), default=5)
    for label, name in enumerate(lib.class_names):
        demos = lib.by_class(label)
        lengths = np.array([d.n_samples for d in demos]) if demos else np.zeros(0, dtype=int)
        n_issues = sum(1 for i in lib.issues if i.class_name == name)
        span = f"{lengths.min()}-{lengths.max()}" if lengths.size else "-"
        lines.append(f"  {label:>2} {name:<{width}}  {len(demos):>4} demos  samples/demo {span:>7}  "
                     f"issues {n_issues}")
    for issue in lib.issues:
        lines.append(f"  issue: {issue}")
    return "\n".join(lines)


def _info_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", help="library: a directory of compound_*.csv or a .npz")


def _cmd_info(args: argparse.Namespace) -> int:
    print(format_info(load_library(args.path)))
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    lib = load_library(args.path)
    for issue in lib.issues:
        print(f"issue: {issue}")
    print(f"{lib.source}: {len(lib.demos)} valid demonstrations in {lib.n_classes} classes, "
          f"{len(lib.issues)} issue(s), features: {describe_features(lib.feature_names)}")
    return 1 if lib.issues else 0


def _convert_args(p: argparse.ArgumentParser) -> None:
    _info_args(p)
    p.add_argument("--out", required=True, metavar="FILE.npz", help="output npz file")


def _cmd_convert(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix != ".npz":
        raise LibraryError(f"--out {str(out)!r}: the native format is a .npz file")
    lib = load_library(args.path)
    save_library(lib, out)
    print(f"wrote {out}: {len(lib.demos)} demonstrations in {lib.n_classes} classes "
          f"({len(lib.issues)} issue(s) recorded, malformed demonstrations left out)")
    return 0


# name -> (help, add_arguments(parser), run(args) -> exit code)
SUBCOMMANDS: dict[str, tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {
    "info": ("classes, demonstrations per class and issues of a library", _info_args, _cmd_info),
    "validate": ("report malformed demonstrations; exit status 1 if any", _info_args, _cmd_validate),
    "convert": ("convert a library (e.g. the paper's CSVs) to the native .npz", _convert_args, _cmd_convert),
    "generate": ("generate a synthetic library of table reaches (IK on the human model; shared/synthetic.py)",
                 add_generate_arguments, run_generate),
}


def _parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Inspect, validate and convert human-motion libraries "
                                     "(a directory of compound_*.csv in the paper's format, or a native .npz).")
    sub = parser.add_subparsers(dest="subcommand", metavar="SUBCOMMAND", required=True)
    for name, (text, add_args, run) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        add_args(p)
        p.set_defaults(run=run)
    return parser


def main(argv: list[str] | None = None, prog: str = "foresight library") -> int:
    """Run ``foresight library SUBCOMMAND ...``; returns the exit status."""
    args = _parser(prog).parse_args(argv)
    with cli_errors(f"{prog} {args.subcommand}"):
        return int(args.run(args))


if __name__ == "__main__":
    sys.exit(main())
