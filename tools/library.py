"""``foresight library``: inspect, validate and convert human-motion libraries.

Sub-commands (each is one ``_cmd_<name>`` function registered in :data:`SUBCOMMANDS`; adding one
means writing its ``add_arguments``/``run`` pair and one entry there):

- ``info PATH``: features (and their mapping to the human model), classes, valid demonstrations per
  class, sample counts, issues.
- ``validate PATH``: print every malformed demonstration; exit status 1 if there is any.
- ``convert PATH --out FILE.npz|DIR``: write the native npz (valid demonstrations and the issue list) or a
  directory of the paper's CSV files (the valid demonstrations).
- ``generate --classes 8 --demos 25 --seed 0 --out PATH``: a synthetic library (shared/synthetic.py),
  as the native npz or the paper's CSV files.
- ``to-keypoints PATH --out DIR``: the library as 3D body keypoints, one CSV per class.
- ``from-keypoints DIR --out FILE.npz``: the 12 features fitted to a keypoint library.

An output directory is the library's own: an earlier library's class files in it are replaced.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from shared.arguments import ArgumentParser
from shared.feature_sets import describe_features, require_mapping
from shared.human import HumanModel, place_in_scene, reach_points
from shared.library import (
    LibraryError,
    MotionLibrary,
    check_wire_limits,
    load_library,
    save_library,
    write_csv_dir,
)
from shared.runtime import cli_errors
from shared.scene import load_scene
from shared.synthetic import FEATURE_SETS, SyntheticConfig, generate_library, load_layout, pelvis_frame
from shared.synthetic_wide import WIDE_FEATURE_NAMES, generate_wide_library

from .png import check_png
from .reach import plot_reach_points

__all__ = ["main", "SUBCOMMANDS", "format_info"]


def format_info(lib: MotionLibrary) -> str:
    """Human-readable summary: the features, one line per class, then the issues."""
    origin = f" (converted from {lib.origin})" if lib.origin and lib.origin != lib.source else ""
    lines = [f"library: {lib.source}{origin}", f"classes: {lib.n_classes}, valid demonstrations: {len(lib.demos)}, "
             f"issues: {len(lib.issues)}, features: {describe_features(lib.feature_names)}"]
    width = max((len(n) for n in lib.class_names), default=5)
    for label, name in enumerate(lib.class_names):
        demos = lib.by_class(label)
        lengths = np.array([d.n_samples for d in demos]) if demos else np.zeros(0, dtype=int)
        mine = [i for i in lib.issues if i.class_name == name]
        n_issues = sum(not i.summary for i in mine) or len(mine)  # "holds no valid demonstration" sums the others
        span = f"{lengths.min()}-{lengths.max()}" if lengths.size else "-"
        lines.append(f"  {label:>2} {name:<{width}}  {len(demos):>4} demos  samples/demo {span:>7}  "
                     f"issues {n_issues}")
    for issue in lib.issues:
        lines.append(f"  issue: {issue}")
    return "\n".join(lines)


def _info_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", help="library: a directory of compound_*.csv or a .npz")


def _out_path(text: str) -> Path:
    """An output path given on the command line; an empty one would be the current directory."""
    if not text.strip():
        raise LibraryError("--out: empty; give the file or directory to write")
    return Path(text)


def _replaced(stale: set[Path]) -> str:
    """A note on an earlier library's files removed from the output directory."""
    return f"; removed {len(stale)} file(s) of an earlier library: {', '.join(sorted(p.name for p in stale))}" \
        if stale else ""


def _cmd_info(args: argparse.Namespace) -> int:
    print(format_info(load_library(args.path, report=False)))
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    lib = load_library(args.path, report=False)
    for issue in lib.issues:
        print(f"issue: {issue}")
    print(f"{lib.source}: {len(lib.demos)} valid demonstrations in {lib.n_classes} classes, "
          f"{len(lib.issues)} issue(s), features: {describe_features(lib.feature_names)}")
    return 1 if lib.issues else 0


def _convert_args(p: argparse.ArgumentParser) -> None:
    _info_args(p)
    p.add_argument("--out", required=True, metavar="FILE.npz|DIR",
                   help="output: FILE.npz (native) or a directory of compound_<m>.csv (paper format)")


def _cmd_convert(args: argparse.Namespace) -> int:
    out = _out_path(args.out)
    if out.suffix and out.suffix != ".npz":
        raise LibraryError(f"--out {str(out)!r}: give a .npz file or a directory (no extension)")
    lib = load_library(args.path, report=False)
    if not lib.demos:
        raise LibraryError(f"library {lib.source}: no valid demonstration, nothing to convert "
                           f"({len(lib.issues)} issue(s); `foresight library validate {args.path}` lists them)")
    if out.suffix == ".npz":
        save_library(lib, out)
        print(f"wrote {out}: {len(lib.demos)} demonstrations in {lib.n_classes} classes "
              f"({len(lib.issues)} issue(s) recorded, malformed demonstrations left out)")
        return 0
    before = set(out.glob("compound_*.csv")) if out.is_dir() else set()
    files = write_csv_dir(lib, out)
    named = "" if [f.stem for f in files] == lib.class_names else \
        f"; classes {', '.join(lib.class_names)} are named {', '.join(f.stem for f in files)} there"
    print(f"wrote {out}/ ({len(files)} CSV files{_replaced(before - set(files))}): {len(lib.demos)} demonstrations "
          f"in {lib.n_classes} classes (malformed demonstrations left out, the CSV format keeps no issue list: "
          f"{len(lib.issues)} not recorded){named}")
    return 0


def _generate_args(p: argparse.ArgumentParser) -> None:
    """Options of ``foresight library generate`` (an ``argparse`` parser)."""
    p.add_argument("--classes", type=int, default=8, help="number of classes (first goals of the layout)")
    p.add_argument("--demos", type=int, default=25, help="demonstrations per class")
    p.add_argument("--seed", type=int, default=0, help="random seed (same seed, same library)")
    p.add_argument("--out", required=True, metavar="PATH",
                   help="output: FILE.npz (native) or a directory of compound_<m>.csv (paper format)")
    p.add_argument("--layout", default=None, help="goal layout TOML or embedded name (default table_8)")
    p.add_argument("--scene", default=None, help="scene the layout's cups refer to (default: the layout's)")
    p.add_argument("--return-to-rest", action="store_true",
                   help="bring the hand back to rest after the reach, as the paper's recordings do")
    p.add_argument("--plot", default=None, metavar="PNG",
                   help="also write a top view of the demonstrations' final hand positions in the scene")
    p.add_argument("--feature-set", choices=FEATURE_SETS, default="herakles",
                   help="herakles: the paper's 12 features (default); wide16: those plus 4 forearm/wrist channels, "
                        "16 features without a mapping to the human model (17 CSV columns; shared/synthetic_wide.py)")


def _cmd_generate(args: argparse.Namespace) -> int:
    """Run ``foresight library generate`` with parsed ``args``; returns the exit status."""
    if args.seed < 0:
        raise LibraryError(f"--seed: must be >= 0, got {args.seed}")
    out = _out_path(args.out)
    if out.suffix and out.suffix != ".npz":
        raise LibraryError(f"--out {str(out)!r}: give a .npz file or a directory (no extension)")
    if args.plot is not None:
        check_png(args.plot, "--plot")
    scene = load_scene(args.scene) if args.scene else None
    lay = load_layout(args.layout, scene)
    cfg = SyntheticConfig(return_to_rest=bool(args.return_to_rest))
    start = time.perf_counter()
    if getattr(args, "feature_set", "herakles") == "wide16":
        if args.plot:
            require_mapping(WIDE_FEATURE_NAMES, "--plot (hand positions in the scene)", "--feature-set wide16")

        lib = generate_wide_library(args.classes, args.demos, args.seed, layout=lay, scene=scene, config=cfg)
    else:
        lib = generate_library(args.classes, args.demos, args.seed, lay, scene, cfg)
    took = time.perf_counter() - start
    check_wire_limits(lib, out)  # what every read refuses is not written
    if out.suffix == ".npz":
        save_library(lib, out)
        what, names = f"{out}", ", ".join(lib.class_names)
    else:
        before = set(out.glob("compound_*.csv")) if out.is_dir() else set()
        files = write_csv_dir(lib, out)
        what = f"{out}/ ({len(files)} CSV files{_replaced(before - set(files))})"
        names = (f"{', '.join(f.stem for f in files)}, as a CSV directory names its classes: "
                 f"{', '.join(lib.class_names)} in that order; an .npz keeps the names")
    print(f"wrote {what}: {len(lib.demos)} demonstrations in {lib.n_classes} classes "
          f"({names}), {cfg.n_samples} samples of {lib.n_features} features each, "
          f"seed {args.seed}, generated in {took:.2f} s")
    if args.plot:
        scene = scene or load_scene(None)
        model = HumanModel()
        if cfg.return_to_rest:
            hand, _ = reach_points(model, [d.features for d in lib.demos], scene)
        else:
            hand = np.array([model.hand_position(place_in_scene(d.features[-1], d.features[0], scene))
                             for d in lib.demos])
        rot, origin = pelvis_frame(scene)
        goals = origin + lay.goals[:lib.n_classes] @ rot.T
        plot_reach_points(hand, np.array([d.label for d in lib.demos]), scene, args.plot,
                          f"synthetic library ({lay.name}, seed {args.seed}): hand at the reach, x = goals", goals)
        print(f"wrote {args.plot}")
    return 0


# name -> (help, add_arguments(parser), run(args) -> exit code)
def _to_keypoints_args(p: argparse.ArgumentParser) -> None:
    _info_args(p)
    p.add_argument("--out", required=True, metavar="DIR", help="the keypoint library's directory")
    p.add_argument("--noise-m", type=float, default=0.0, help="Gaussian noise per axis, metres")
    p.add_argument("--drop", type=float, default=0.0, help="fraction of frames left out")
    p.add_argument("--missing", type=float, default=0.0, help="fraction of frames with one point left empty")
    p.add_argument("--seed", type=int, default=0, help="seed of the noise, drops and missing points")


def _cmd_to_keypoints(args: argparse.Namespace) -> int:
    from shared.keypoints.library import write_keypoint_library

    if args.seed < 0:
        raise LibraryError(f"--seed: must be >= 0, got {args.seed}")
    for name in ("noise_m", "drop", "missing"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0 and (name == "noise_m" or value < 1)):
            raise LibraryError(f"--{name.replace('_', '-')}: must be >= 0{'' if name == 'noise_m' else ' and < 1'}, "
                               f"got {value}")
    out = _out_path(args.out)
    lib = load_library(args.path, report=False)
    before = set(out.glob("*.csv")) if out.is_dir() else set()
    try:
        files = write_keypoint_library(lib, out, args.noise_m, args.drop, args.missing, args.seed)
    except ValueError as exc:  # no mapping to the human model: nothing was written
        raise LibraryError(str(exc)) from None
    print(f"wrote {len(files)} keypoint files to {out}: {len(lib.demos)} demonstrations"
          f"{_replaced(before - set(files))}")
    return 0


def _from_keypoints_args(p: argparse.ArgumentParser) -> None:
    from shared.keypoints.layouts import LAYOUTS

    p.add_argument("path", help="a keypoint library: a directory of <class>.csv")
    p.add_argument("--out", required=True, metavar="FILE.npz", help="the motion library to write")
    p.add_argument("--layout", default="foresight", choices=LAYOUTS, help="how the CSVs name their points")


def _cmd_from_keypoints(args: argparse.Namespace) -> int:
    from shared.keypoints.library import fit_keypoint_library

    out = _out_path(args.out)
    if out.suffix != ".npz":
        raise LibraryError(f"--out {str(out)!r}: the native format is a .npz file")
    if not Path(args.path).is_dir():
        raise LibraryError(f"keypoint library {args.path!r}: not a directory")
    try:
        lib, report = fit_keypoint_library(Path(args.path), args.layout)
    except ValueError as exc:
        raise LibraryError(str(exc)) from None
    save_library(lib, out)
    for issue in lib.issues:
        print(f"left out: {issue}", file=sys.stderr)
    print(f"wrote {out}: {len(lib.demos)} demonstrations in {lib.n_classes} classes"
          f"{f', {len(lib.issues)} left out (above)' if lib.issues else ''}; {report.line()}")
    return 0


SUBCOMMANDS: dict[str, tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {
    "info": ("classes, demonstrations per class and issues of a library", _info_args, _cmd_info),
    "validate": ("report malformed demonstrations; exit status 1 if any", _info_args, _cmd_validate),
    "convert": ("convert a library (e.g. the paper's CSVs) to the native .npz, or to the paper's CSVs",
                _convert_args, _cmd_convert),
    "generate": ("generate a synthetic library of table reaches (IK on the human model; shared/synthetic.py)",
                 _generate_args, _cmd_generate),
    "to-keypoints": ("write a library as 3D body keypoints, one CSV per class (optionally noisy, with drops)",
                     _to_keypoints_args, _cmd_to_keypoints),
    "from-keypoints": ("fit the 12 features to a keypoint library (one CSV per class): a motion library",
                       _from_keypoints_args, _cmd_from_keypoints),
}


def _parser(prog: str) -> argparse.ArgumentParser:
    parser = ArgumentParser(prog=prog, description="Inspect, validate and convert human-motion libraries "
                                     "(a directory of compound_*.csv in the paper's format, or a native .npz).")
    sub = parser.add_subparsers(dest="subcommand", metavar="{" + ",".join(SUBCOMMANDS) + "}", required=True)
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
