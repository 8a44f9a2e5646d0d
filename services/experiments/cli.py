"""foresight eval: the paper's experiments through the product (the list: :data:`~.commands.EXPERIMENTS`).

Every run goes through the four services (in-process, loopback Zenoh, lock-step, seeded): the same
command prints the same numbers every time.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Iterator
from pathlib import Path

from services.planner.config import MAX_ROLLOUTS, StompConfig
from services.predictor.volumes import VOLUMES
from shared import strict_json
from shared.arguments import ArgumentParser
from shared.atomic_file import ready_to_write
from shared.protocol.limits import MAX_PERIOD_S, MIN_PERIOD_S
from shared.runtime import UserError, cli_errors, help_text, setup_logging
from shared.scene import SCENE_HELP
from tools.png import check_png

from .commands import EXPERIMENTS
from .planners import Timing
from .protocol import DEFAULT_PACES, PAPER, PROTOCOLS, SWITCH_SCENE, TABLE1_SCENE, TRIALS, protocol

__all__ = ["main"]


def _common(p: argparse.ArgumentParser, scene: str) -> None:
    p.add_argument("--library", default="synthetic", help="motion library: 'synthetic' (the embedded synthetic "
                   "library, generated for the scene's cups) or a path (dir of compound_*.csv or .npz); "
                   "default: synthetic")
    default = f"{scene}; with --protocol paper the authors' scene, {PAPER.table1_scene}" if scene == TABLE1_SCENE \
        else scene
    p.add_argument("--scene", default=None, help=f"{SCENE_HELP} (default: {default})")
    p.add_argument("--steps", type=int, default=Timing.steps, help="replanning steps per run (default: 20)")
    p.add_argument("--period-s", type=float, default=Timing.period_s, help="simulated seconds the robot executes "
                   "per step (default: 0.5, the paper's planning time per step)")
    p.add_argument("--iterations", type=int, default=None, help="STOMP iterations per step "
                   "(default: the protocol's, 50 in the product's, 51 in the paper's)")
    p.add_argument("--robot-speed", type=float, default=Timing.robot_speed, help="fraction of the PR2's joint "
                   "velocity limits (default: 0.25)")
    p.add_argument("--rollouts", type=int, default=None, help="STOMP rollouts per iteration (default: 10, the "
                   "planner's and the paper authors')")
    p.add_argument("--reuse", type=int, default=None, help="rollouts of the previous iteration STOMP reuses, the "
                   "best first (default: 5, the planner's and the paper authors')")
    p.add_argument("--components", type=int, default=20, help="Gaussians per class (default: 20, the paper's)")
    p.add_argument("--w-human", type=float, default=None, help="weight of the planner's human cost (default: the "
                   "planner's, 1); for ablations")
    p.add_argument("--volume", choices=VOLUMES, default=None, help="volume method of the held-out prediction "
                   "models (foresight train --volume; default: the trainer's)")
    p.add_argument("--models-dir", type=Path, default=Path("models/experiments"), help="held-out models cache")
    p.add_argument("--work-dir", type=Path, default=Path("runs/experiments"), help="scratch files of the runs")
    p.add_argument("--no-compile", action="store_true", help="run the planner's cost and STOMP's steps "
                   "eagerly (no torch.compile)")
    p.add_argument("--protocol", choices=PROTOCOLS, default="product", help="product: the product's pace, costs and "
                   "measure (default); paper: the paper's authors' protocol, from their code (docs/experiments.md)")
    p.add_argument("--trials", choices=TRIALS, default="auto", help="the human's motions: authors (the authors' "
                   "motions of the paper's library, 25-29 / 77), cup (the class nearest the human's cup), auto "
                   "(authors with --protocol paper on the paper's library, else cup)")
    p.add_argument("--json", action="store_true", help="print one JSON object (progress goes to stderr)")


@contextlib.contextmanager
def _user_errors() -> Iterator[None]:
    """User-fixable failures in one line, not a traceback.

    Bad scene, library or model files, and a run whose planner failed (no reachable goal in the scene, say).
    """
    from services.predictor.model import ModelError
    from shared.library import LibraryError
    from shared.scene import SceneError

    from .harness import RunFailed

    try:
        yield
    except (SceneError, LibraryError, ModelError) as exc:
        raise UserError(str(exc)) from None
    except RunFailed as exc:
        raise UserError(f"a run failed: {exc}") from None


def _timing(args: argparse.Namespace) -> Timing:
    """The runs' timing, checked with the options' names before any model is trained.

    The planner and the executor check them too, but after the training and by their own names: ``--rollouts 3``
    failed minutes in as "planner.stomp.reuse must be in [0, rollouts - 1 = 2], got 5", an option never given.
    """
    t = Timing(args.steps, args.period_s, args.iterations, args.robot_speed, args.rollouts, args.reuse)
    if (t.rollouts is not None and not 2 <= t.rollouts <= MAX_ROLLOUTS) or (t.reuse is not None and t.reuse < 0):
        raise UserError(f"--rollouts must be in [2, {MAX_ROLLOUTS}] and --reuse >= 0, got {t.rollouts} and {t.reuse}")
    prot = protocol(args.protocol)
    rollouts, reuse = (next(v for v in (asked, getattr(prot, key), getattr(StompConfig, key)) if v is not None)
                       for key, asked in (("rollouts", t.rollouts), ("reuse", t.reuse)))
    if reuse >= rollouts:  # each defaults to the protocol's, else the planner's: say which was not given
        def said(key: str, value: int, asked: int | None) -> str:
            whose = f"the {prot.name} protocol's" if getattr(prot, key) is not None else "the planner's"
            return f"--{key} {value}" + ("" if asked is not None else f" (its default, {whose})")

        given = [said("rollouts", rollouts, t.rollouts), said("reuse", reuse, t.reuse)]
        raise UserError(f"--reuse must be below --rollouts (the best rollouts kept for the next iteration), got "
                        f"{' and '.join(given)}")
    if not MIN_PERIOD_S <= t.period_s <= MAX_PERIOD_S:  # the executor's clock tick, on the wire
        raise UserError(f"--period-s must be in [{MIN_PERIOD_S:g}, {MAX_PERIOD_S:g}] s (a clock tick's period), "
                        f"got {t.period_s}")
    if t.steps < 1 or (t.iterations is not None and t.iterations < 1) or not 0 < t.robot_speed <= 1:
        raise UserError("--steps and --iterations must be >= 1, --robot-speed in (0, 1]")
    if args.components < 1:
        raise UserError(f"--components must be >= 1, got {args.components}")
    if args.w_human is not None and not (math.isfinite(args.w_human) and args.w_human >= 0):
        raise UserError(f"--w-human must be a finite weight >= 0, got {args.w_human}")
    return t


def _doc(module: str) -> str:
    """A module's docstring as ``--help`` prose (reST literals shown plain), read from its source.

    Not imported: the experiments' modules load the services and torch, 12 s for ``foresight eval --help``.
    """
    import ast

    source = (Path(__file__).parent / f"{module}.py").read_text(encoding="utf-8")
    return help_text(ast.get_docstring(ast.parse(source), clean=False) or "").replace("`", "")


def _parser(prog: str) -> argparse.ArgumentParser:
    listing = "\n".join(f"    {prog} {name:<13} {text}" for name, text in EXPERIMENTS.items())
    intro, rest = __doc__.split("\n", 1)
    description = help_text(f"{intro.split(' (')[0]}:\n\n{listing}\n{rest}")
    parser = ArgumentParser(prog=prog, description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True, metavar="{" + ",".join(EXPERIMENTS) + "}")
    sub.add_parser("recognition", help=EXPERIMENTS["recognition"], add_help=False)
    sub.add_parser("novelty", help=EXPERIMENTS["novelty"], add_help=False)
    p = sub.add_parser("interference", help=EXPERIMENTS["interference"],
                       description=_doc("interference"),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(p, TABLE1_SCENE)
    p.add_argument("--demos", type=int, default=5, help="held-out demonstrations (default: 5)")
    p.add_argument("--seeds", type=int, default=10, help="runs per demonstration and planner (default: 10)")
    p.add_argument("--robot-cup", default="red_cup", help="the robot's one task (default: red_cup)")
    p.add_argument("--human-cup", default="blue_cup", help="the cup the human reaches for (default: blue_cup)")
    p.add_argument("--basic-every-demo", action="store_true",
                   help="plan basic STOMP on every demonstration at every seed (default: on every demonstration at "
                        "seed 0, then, where its paths agree to the bit, once per seed and scored against each)")
    p = sub.add_parser("switch", help=EXPERIMENTS["switch"],
                       description=_doc("switch"),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(p, SWITCH_SCENE)
    p.add_argument("--human-cup", default="red_cup", help="the cup the human reaches for (default: red_cup)")
    p.add_argument("--demos", type=int, default=0, help="demonstrations of the class, each held out in turn "
                   "(default 0: all)")
    p.add_argument("--seed", type=int, default=0, help="STOMP seed of every run (default: 0)")
    p.add_argument("--plot", type=Path, default=Path("runs/plots/switch.png"), help="Fig. 9 PNG")
    p = sub.add_parser("occupancy", help=EXPERIMENTS["occupancy"],
                       description=_doc("occupancy"), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--library", default="synthetic", help="motion library: 'synthetic' (the embedded synthetic "
                   "library) or a path (dir of compound_*.csv or .npz); default: synthetic")
    p.add_argument("--scene", default="", help=f"{SCENE_HELP} (default: pr2_two_cups)")
    p.add_argument("--methods", default=",".join(VOLUMES), help="volume methods compared, comma-separated "
                   f"(default: {','.join(VOLUMES)})")
    p.add_argument("--per-class", type=int, default=0, help="held-out demonstrations per class, evenly spread "
                   "(default 0: every one)")
    p.add_argument("--components", type=int, default=20, help="Gaussians per class (default: 20)")
    p.add_argument("--resolution", type=float, default=None, help="voxel edge in metres (default: the scene's)")
    p.add_argument("--n-jobs", type=int, default=2, help="worker processes (default: 2)")
    p.add_argument("--example", type=int, default=0, help="held-out demonstration drawn in the PNG (its position "
                   "in the held-out order; default 0)")
    p.add_argument("--out", type=Path, default=Path("runs/occupancy"), help="directory of the PNG "
                   "(default: runs/occupancy)")
    p.add_argument("--json", action="store_true", help="print one JSON object (progress goes to stderr)")
    p = sub.add_parser("volumes", help=EXPERIMENTS["volumes"], description=_doc("volumes"),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--library", default="synthetic", help="motion library: 'synthetic' (the embedded synthetic "
                   "library) or a path (dir of compound_*.csv or .npz); default: synthetic")
    p.add_argument("--volumes", default=",".join(VOLUMES), help=f"volume methods, comma-separated (default: "
                   f"{','.join(VOLUMES)})")
    p.add_argument("--demos", type=int, default=5, help="Table I held-out demonstrations (default: 5)")
    p.add_argument("--seeds", type=int, default=10, help="Table I runs per demonstration (default: 10)")
    p.add_argument("--switch-demos", type=int, default=0, help="switch demonstrations, each held out in turn "
                   "(default 0: all)")
    p.add_argument("--components", type=int, default=20, help="Gaussians per class (default: 20, the paper's)")
    p.add_argument("--models-dir", type=Path, default=Path("models/experiments"), help="held-out models cache")
    p.add_argument("--work-dir", type=Path, default=Path("runs/experiments"), help="scratch files of the runs")
    p.add_argument("--no-compile", action="store_true", help="run the planner's cost and STOMP's steps eagerly")
    p.add_argument("--json", action="store_true", help="print one JSON object (progress goes to stderr)")
    p = sub.add_parser("pace", help=EXPERIMENTS["pace"],
                       description=_doc("pace"), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--libraries", default="synthetic", help="comma-separated: 'synthetic' and/or paths "
                   "(default: synthetic)")
    p.add_argument("--library", default="", metavar="PATH", help="the paper's motion library (a directory of "
                   "compound_*.csv or an .npz): run it beside the synthetic one (--libraries synthetic,PATH)")
    p.add_argument("--protocols", default="product,paper", help="comma-separated (default: product,paper)")
    for prot, paces in DEFAULT_PACES.items():
        p.add_argument(f"--{prot}-paces", default=",".join(f"{x:g}" for x in paces),
                       help=f"paces of the {prot} protocol (default: {','.join(f'{x:g}' for x in paces)})")
    p.add_argument("--demos", type=int, default=5, help="held-out demonstrations per point (default: 5)")
    p.add_argument("--seeds", type=int, default=2, help="seeds per demonstration (default: 2)")
    p.add_argument("--iterations", type=int, default=None, help="STOMP iterations per step (default: each "
                   "protocol's, 50 / 51); fewer for a quick look")
    p.add_argument("--components", type=int, default=20, help="Gaussians per class (default: 20)")
    p.add_argument("--volume", choices=VOLUMES, default=None, help="the product protocol's held-out models' volume "
                   "method (foresight train --volume; default: the trainer's); the paper protocol uses its own")
    p.add_argument("--models-dir", type=Path, default=Path("models/experiments"), help="held-out models cache")
    p.add_argument("--work-dir", type=Path, default=Path("runs/experiments"), help="scratch files of the runs")
    p.add_argument("--plot", type=Path, default=Path("runs/plots/pace.png"), help="the PNG")
    p.add_argument("--no-compile", action="store_true", help="run the planner's cost and STOMP's steps eagerly")
    p.add_argument("--json", action="store_true", help="print one JSON object (progress goes to stderr)")
    from .report import add_report_arguments

    add_report_arguments(sub.add_parser("all", help=EXPERIMENTS["all"],
                                        description=_doc("report"),
                                        formatter_class=argparse.RawDescriptionHelpFormatter))
    return parser


def _occupancy(args: argparse.Namespace, out) -> int:
    from shared.scene import load_scene

    from .heldout import load_experiment_library, short_name
    from .occupancy import OccupancyConfig, plot_occupancy, run_occupancy

    if args.per_class < 0 or args.components < 1 or args.n_jobs < 1:
        raise UserError("--per-class must be >= 0, --components and --n-jobs >= 1")
    from services.predictor.train import check_resolution

    check_resolution(args.resolution)
    ready_to_write(args.out, directory=True)  # before the work: a file in the way lost it all
    scene = load_scene(args.scene or None)
    lib = load_experiment_library(args.library, scene)
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    res = run_occupancy(lib, scene, OccupancyConfig(methods=methods, per_class=args.per_class,
                                                    components=args.components, resolution=args.resolution,
                                                    n_jobs=args.n_jobs, example=args.example), out)
    png = plot_occupancy(res, Path(args.out) / f"occupancy-{short_name(lib.source)}.png")
    if args.json:
        print(strict_json.dumps({**res.to_json(), "plot": str(png)}))
    else:
        print("\n".join([*res.lines(), f"plot: {png}"]))
    return 0


def _volumes(args: argparse.Namespace, out) -> int:
    from .volumes import VolumesConfig, run_volumes

    volumes = tuple(v.strip() for v in args.volumes.split(",") if v.strip())
    bad = [v for v in volumes if v not in VOLUMES]
    if bad or not volumes:
        raise UserError(f"--volumes: {', '.join(bad) or 'none given'}; choose from {', '.join(VOLUMES)}")
    if args.demos < 1 or args.seeds < 1 or args.switch_demos < 0 or args.components < 1:
        raise UserError("--demos, --seeds and --components must be >= 1, --switch-demos >= 0")
    res = run_volumes(VolumesConfig(library=str(args.library), volumes=volumes, demos=args.demos, seeds=args.seeds,
                                    switch_demos=args.switch_demos, components=args.components,
                                    models_dir=args.models_dir, work_dir=args.work_dir), out,
                      compile=not args.no_compile)
    if args.json:
        print(strict_json.dumps(res.to_json()))
    else:
        print("\n".join(res.lines()))
    return 0


def _pace(args: argparse.Namespace, out) -> int:
    from .pace import PaceConfig, plot_pace, run_pace

    protocols = tuple(p.strip() for p in args.protocols.split(",") if p.strip())
    bad = [p for p in protocols if p not in PROTOCOLS]
    if bad or not protocols:
        raise UserError(f"--protocols: {', '.join(bad) or 'none given'}; choose from {', '.join(PROTOCOLS)}")
    try:
        paces = {p: tuple(float(x) for x in getattr(args, f"{p}_paces").split(",") if x.strip()) for p in PROTOCOLS}
    except ValueError as exc:
        raise UserError(f"--*-paces: comma-separated numbers ({exc})") from None
    if any(not v or not all(x > 0 and math.isfinite(x) for x in v) for v in paces.values()):
        raise UserError("--product-paces and --paper-paces: numbers > 0")
    if any(x > 1 for x in paces["product"]):
        raise UserError("--product-paces: fractions of the velocity limits, in (0, 1]")
    if args.demos < 1 or args.seeds < 1 or args.components < 1:
        raise UserError("--demos, --seeds and --components must be >= 1")
    libraries = tuple(x.strip() for x in args.libraries.split(",") if x.strip())
    if args.library:
        libraries = (*dict.fromkeys((*libraries, args.library)),)
    if args.iterations is not None and args.iterations < 1:
        raise UserError(f"--iterations must be >= 1, got {args.iterations}")
    check_png(str(args.plot), "--plot")  # x.jpg ran the whole sweep; 'fig9' was written fig9.png, said fig9
    ready_to_write(args.plot)
    from shared.library import load_library

    from .heldout import SYNTHETIC

    for library in libraries:  # each library read now: a missing one was said after the others' runs
        if library != SYNTHETIC:
            load_library(library)
    res = run_pace(PaceConfig(libraries=libraries, protocols=protocols, paces=paces, demos=args.demos,
                              seeds=args.seeds, components=args.components, volume=args.volume,
                              models_dir=args.models_dir,
                              work_dir=args.work_dir, timing=Timing(iterations=args.iterations)),
                   out, compile=not args.no_compile)
    png = plot_pace(res, args.plot)
    if args.json:
        print(strict_json.dumps({**res.to_json(), "plot": str(png)}))
    else:
        print("\n".join([*res.lines(), f"plot: {png}"]))
    return 0


def main(argv: list[str] | None = None, prog: str = "foresight eval") -> int:
    """``foresight eval ...``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "recognition":
        from services.predictor.recognition import main as recognition_main

        return recognition_main(argv, prog=prog)
    if argv and argv[0] == "novelty":
        from services.predictor.novelty_eval import main as novelty_main

        return novelty_main(argv, prog=prog)
    args = _parser(prog).parse_args(argv)
    setup_logging("WARNING")
    with cli_errors(f"{prog} {args.what}"), _user_errors():
        if args.what == "all":
            from .report import run_report

            return run_report(args)
        out = (lambda line: print(line, file=sys.stderr, flush=True)) if args.json else \
            (lambda line: print(line, flush=True))
        if args.what == "occupancy":
            return _occupancy(args, out)
        if args.what == "volumes":
            return _volumes(args, out)
        if args.what == "pace":
            return _pace(args, out)
        timing = _timing(args)
        default_scene = (protocol(args.protocol).table1_scene if args.what == "interference" else SWITCH_SCENE)
        common = {"library": str(args.library), "scene": args.scene or default_scene, "timing": timing,
                  "components": args.components, "models_dir": args.models_dir, "work_dir": args.work_dir,
                  "w_human": args.w_human, "volume": args.volume, "protocol": args.protocol,
                  "trials": args.trials}
        if args.what == "interference" and (args.demos < 1 or args.seeds < 1):
            raise UserError(f"--demos and --seeds must be >= 1, got {args.demos} and {args.seeds}")
        if args.what == "switch" and (args.demos < 0 or args.seed < 0):
            raise UserError(f"--demos must be >= 0 (0: all) and --seed >= 0, got {args.demos} and {args.seed}")
        if args.what == "switch":
            check_png(str(args.plot), "--plot")
            ready_to_write(args.plot)
        if args.what == "interference":
            from .interference import InterferenceConfig, run_interference

            res = run_interference(InterferenceConfig(robot_cup=args.robot_cup, human_cup=args.human_cup,
                                                      demos=args.demos, seeds=args.seeds,
                                                      basic_once=not args.basic_every_demo, **common),
                                   out, compile=not args.no_compile)
            lines, data = res.lines(), res.to_json()
        else:
            from .switch import SwitchConfig, plot_switch, run_switch

            sres = run_switch(SwitchConfig(human_cup=args.human_cup, demos=args.demos, seed=args.seed, **common),
                              out, compile=not args.no_compile)
            png = plot_switch(sres, args.plot)
            lines, data = [*sres.lines(), f"plot: {png}"], {**sres.to_json(), "plot": str(png)}
        if args.json:
            print(strict_json.dumps(data))
        else:
            print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
