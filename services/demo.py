"""``foresight demo`` (``make demo``): the paper's Table I situation with the four services as processes.

The default run is the one `foresight eval pace` found prediction to matter in: the scene of the
paper's Table I (``pr2_two_cups_side``), the human reaching for the blue cup, across the robot's way
to the red one (the robot's one goal, ``--goals red_cup``, as in Table I and the pace sweep), and the
robot moving at 0.1 of the PR2's velocity limits with a replanning step of 0.5 s (docs/experiments.md,
"Across the robot's pace"). ``--compare`` runs it with the paper's baselines too and says whether
prediction kept the robot further from the human. ``--goals blue_cup,red_cup`` lets the robot choose
its cup each step too (the paper's Fig. 9).

1. Load the motion library (default: the embedded synthetic one) and pick the demonstration the human
   performs (of ``--human-class``).
2. Train the prediction model without that demonstration, unless it is cached in ``models/``.
3. Be the Zenoh router on a free loopback port and start the replayer, predictor, planner and
   executor, each as ``python -m services.<name> --connect <router>`` in its own process group, with
   their logs and the MCAP in the run's own directory, ``runs/demo/<UTC time>-<mode>/``
   (``runs/demo/latest`` points to the newest run whose services started; one stopped before its executor
   opened an MCAP log hands it back to the run before, unless there is none: then it points to that run's
   service logs).
4. Lock-step (default): the executor ticks ``--steps`` replanning steps; the human advances by a fixed
   number of samples per step (the paper's protocol); then the robot finishes its last plan.
   Real time: the replayer streams at ``--rate-hz``, the planner replans every ``--period-s``, the
   executor runs ``steps x period`` seconds. While it runs, print one table: a header, then a row per
   replanning step as its plan arrives (step, seconds into the run, chosen goal, each candidate's
   cost, planning time, the predictor's belief).
5. Stop everything (SIGTERM, then SIGKILL after a bounded wait) and print the summary: the step where
   the robot switched goal, the step and time it reached it, the interference with the prediction
   and the contact with the real human (with ``--compare``, per planner and a verdict), the MCAP
   path, and a PNG of the run (``run.png``: the robot's path around the predicted volume, the human,
   the chosen goal per step).

Ctrl-C (or SIGTERM) at any moment stops the services in order, the executor first, which finishes
its MCAP; the demo then says after how many of its steps it stopped (plans, in real time), that the log
is complete, and where the run's files are; it exits with status 130 (``make demo`` takes that as its end).
With ``--compare`` a run cut short is marked in the table and no verdict is given.

Exit status: 0 a whole run; 1 a service failed (at start; dead or hung in lock-step; the executor dead or hung), a
timeout, or a run that went to its end but not whole (a service dead or restarted in real time, lock-step ticks that
went on without their plan: "faults during the run"); 2 bad input; 3 a second signal while it stops; 4 its MCAP log
is not complete (a full disk: the closing ``MCAP log: PATH — INCOMPLETE: ...`` line says how much it lost); 130
interrupted (``services.demo_status``).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import socket
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from services.demo_closing import closing_lines, picture
from services.demo_dirs import MAIN_VARIANT, RunDirectory, forced_exit_note, variant_dir
from services.demo_inputs import check_inputs, share_config_file
from services.view.config import DEFAULT_PORT
from shared import strict_json
from shared.arguments import ArgumentParser
from shared.atomic_file import make_parent
from shared.config import LOG_LEVELS, ConfigError, add_config_arguments, check_prefix, opt, resolve_config
from shared.protocol.limits import MAX_PERIOD_S, MIN_PERIOD_S
from shared.runtime import cli_errors, help_text, setup_logging, stop_on_signals
from shared.scene import SCENE_HELP, load_scene
from shared.security.acl import refuse_ros2_keys

if TYPE_CHECKING:  # the run's modules load torch and matplotlib (9 s): imported when a run starts, not for --help
    from services.demo_run import RunRecord
    from services.scenario import Summary

__all__ = ["DemoConfig", "run_demo", "main"]

log = logging.getLogger("foresight.demo")

STOP_GRACE_S = 90.0
"""Seconds ``foresight demo`` may take to stop its services after SIGINT/SIGTERM (each has a bounded stop)."""


@dataclasses.dataclass
class DemoConfig:
    """Options of ``foresight demo`` (``[demo]`` in the TOML file)."""

    library: Path | None = opt(None, help="motion library (dir of compound_*.csv or .npz); unset = the embedded "
                                    "synthetic library")
    mode: str = opt("lockstep", choices=("lockstep", "realtime"),
                    help="lockstep: deterministic, one replanning step per clock tick; realtime: wall clock")
    steps: int = opt(20, help="replanning steps (the paper: 20)")
    seed: int = opt(0, help="seed of the demonstration choice and of STOMP")
    human_class: str = opt("blue_cup", help="class (name or index) the human performs. blue_cup: the reach of the "
                           "paper's Table I, across the robot's way to the red cup. An empty value (\"\") names "
                           "another: the class red_cup, the reach of the paper's Fig. 8 (the robot switches cups), "
                           "or the library's last class if it has none")
    goals: str = opt("red_cup", help="cups the robot plans for, comma-separated, in order (empty: every cup of the "
                     "scene). red_cup: the robot's one task in the paper's Table I, the situation "
                     "`foresight eval pace` measured; blue_cup,red_cup: the robot also chooses the cup each step "
                     "(the paper's Fig. 9)")
    scene: str = opt("pr2_two_cups_side", help=f"{SCENE_HELP}; pr2_two_cups_side: the scene of the paper's Table I")
    method: str = opt("prediction", choices=("prediction", "current"),
                      help="occupancy the planner avoids: the early prediction, or the current posture only")
    human_cost: bool = opt(True, help="plan with the human-penetration cost (off: the paper's 'basic STOMP')")
    compare: bool = opt(False, help="run the scenario three times (prediction, current occupancy, no human cost) "
                        "and compare their interference with the final prediction (the paper's Table I)")
    components: int = opt(-1, help="Gaussians per class when training (-1: the trainer's default, 20)")
    robot_speed: float = opt(0.1, help="fraction of the PR2's joint velocity limits the planner times trajectories "
                             "with (the planner's --velocity-scale). 0.1: a pace at which `foresight eval pace` "
                             "measured that prediction keeps the robot off the human (docs/experiments.md)")
    period_s: float = opt(0.5, help="replanning period (simulated s per step in lock-step, wall s in real time; 0.5: "
                          "the experiments', the paper's 50 STOMP iterations)")
    finish: bool = opt(True, help="after the last step the robot goes on to its goal: lockstep, it executes the rest "
                       "of its last plan (the executor's --finish-path); realtime, it goes on replanning until it is "
                       "there, at most as long again as the run (--finish-s)")
    rate_hz: float = opt(30.0, help="real time: poses per second (keypoint frames with --human keypoints)")
    human: str = opt("replayer", choices=("replayer", "keypoints"), help="how the human comes in: replayer, the "
                     "demonstration's posture features; keypoints, the same demonstration as body keypoints (the "
                     "human model's joint positions, see --keypoint-noise-m) played by `foresight tracker --from`, "
                     "which fits the features back as it would a live person's (real time only; docs/keypoints.md)")
    keypoint_noise_m: float = opt(0.0, help="--human keypoints: Gaussian noise per axis on the keypoints (m; a depth "
                                  "camera's skeleton: about 0.02), seeded by --seed")
    models_dir: Path = opt(Path("models"), help="where trained models are cached")
    run_dir: Path = opt(Path("runs/demo"), help="service logs and the MCAP file go here")
    ros2: bool = opt(False, help="also run the ROS 2 gateway (foresight ros2): the run as ROS 2 topics over "
                     "rmw_zenoh on the demo's router (docs/ros2.md)")
    robot: str = opt("sim", choices=("sim", "ros2", "ros2-sim"), help="what the executor drives: sim, its own "
                     "simulated arm; ros2, a ROS 2 robot on the demo's router (its /joint_states in, plans to "
                     "/r_arm_controller/joint_trajectory); ros2-sim, the same with `foresight simrobot` started as the "
                     "robot (docs/ros2.md)")
    live: int = opt(0, help="also serve the run live to the Foxglove app on ws://127.0.0.1:PORT (the executor serves "
                    "the scene it logs; bare --live: 8765, the app's default; docs/live-view.md); 0: off")
    security: Path | None = opt(None, help="mutual TLS and access control: the directory of `foresight security "
                                "init`; the demo's router and every service present their role's certificate")
    prepare: Path | None = opt(None, help="only write the scenario's inputs and a config file for the services to this "
                               "directory (DIR/foresight.toml: run each service with --config DIR/foresight.toml), "
                               "then exit; what compose.yaml's prepare service runs")
    port: int = opt(0, help="loopback TCP port of the demo's Zenoh router (0 = a free port)")
    prefix: str = opt("foresight", help="key-expression prefix")
    timeout: float = opt(900.0, help="give up after this many seconds")
    restart: bool = opt(False, help="start a service that dies or hangs during the run again (at most 3 times; "
                        "the human's source starts its demonstration over); without it the run carries on without "
                        "the service (the executor holds the robot). Either way the run is marked as not whole and "
                        "--compare gives no verdict on it")
    json: bool = opt(False, help="print one JSON object with the summary (progress goes to stderr)")
    log_level: str = opt("WARNING", choices=LOG_LEVELS, help="log level of the demo (DEBUG: the services' logs too, "
                         "e.g. the planner's line per plan; FORESIGHT_<SERVICE>_LOG_LEVEL sets one service's)")

    @property
    def run_s(self) -> float:
        """The run's length, ``steps x period_s`` (simulated s in lock-step, wall s in real time)."""
        return self.steps * self.period_s

    @property
    def finish_s(self) -> float:
        """How long a real-time run with ``finish`` may go on to its goal: the run's length again; else 0.

        The executor's ``finish_s``; the demo's rows, notes and title follow it.
        """
        return self.run_s if self.finish and self.mode == "realtime" else 0.0

    def validate(self) -> None:
        """Check value ranges."""
        if self.steps < 1:
            raise ConfigError(f"demo.steps: must be >= 1, got {self.steps}")
        check_prefix(self.prefix, "demo.prefix")
        for name in ("period_s", "rate_hz", "timeout"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"demo.{name}: must be > 0, got {getattr(self, name)}")
        if not MIN_PERIOD_S <= self.period_s <= MAX_PERIOD_S:  # the clock tick's period on the wire
            raise ConfigError(f"demo.period_s: must be in [{MIN_PERIOD_S:g}, {MAX_PERIOD_S:g}] s (a clock tick's "
                              f"period, docs/protocol.md), got {self.period_s}")
        if self.seed < 0:
            raise ConfigError(f"demo.seed: must be >= 0, got {self.seed}")
        if self.components < -1:
            raise ConfigError(f"demo.components: must be -1 (the trainer's default), 0 (chosen by BIC) or more, got "
                              f"{self.components}")
        if self.human == "keypoints" and self.mode != "realtime":
            raise ConfigError("demo.human = keypoints: the tracker takes a sensor's frames as they come, in real time; "
                              "add --mode realtime")
        if not (self.keypoint_noise_m >= 0 and self.keypoint_noise_m < 1):
            raise ConfigError(f"demo.keypoint_noise_m: must be in [0, 1) m, got {self.keypoint_noise_m}")
        if not 0 < self.robot_speed <= 1:
            raise ConfigError(f"demo.robot_speed: must be in (0, 1], got {self.robot_speed}")
        if self.ros2 or self.robot != "sim":
            refuse_ros2_keys("" if self.security is None else str(self.security),
                             f"demo.{'ros2' if self.ros2 else 'robot'}", "demo.security")
        if self.security is not None and not Path(self.security).is_dir():
            raise ConfigError(f"demo.security: {self.security} is not a directory (make one with `foresight security "
                              "init DIR`)")
        if not 0 <= self.port < 65536:
            raise ConfigError(f"demo.port: must be 0..65535, got {self.port}")
        if not 0 <= self.live < 65536:
            raise ConfigError(f"demo.live: must be a port 1..65535 (0: off), got {self.live}")


VARIANTS = ((MAIN_VARIANT, {"method": "prediction", "human_cost": True}),
            ("current occupancy", {"method": "current", "human_cost": True}),
            ("no human cost", {"method": "prediction", "human_cost": False}))
"""The planners ``--compare`` runs: the paper's method and its two baselines (Fig. 8/9, Table I)."""


def _check_live_port(cfg: DemoConfig) -> None:
    """``--live PORT`` must be free before the services start: the executor found out 20 s later."""
    if not cfg.live:
        return
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # a port in TIME_WAIT is free to the server
        try:
            probe.bind(("127.0.0.1", cfg.live))
        except OSError as exc:
            raise ConfigError(f"demo.live: port {cfg.live} on 127.0.0.1 is taken ({exc.strerror}); give another "
                              "(--live PORT)") from None


def _check_models_dir(cfg: DemoConfig) -> None:
    """The model cache must be usable before a minute of training, not after it."""
    models = Path(cfg.models_dir)
    try:
        make_parent(models / "model.npz")
    except OSError as exc:
        raise ConfigError(f"demo.models_dir: {exc.filename or models}: {exc.strerror or exc}") from None
    if not os.access(models, os.W_OK | os.X_OK):
        raise ConfigError(f"demo.models_dir: {models} is not writable (the prediction model is cached there)")


def run_demo(cfg: DemoConfig, stop: threading.Event, out: Callable[[str], None] = print,
             on_start: Callable[[Path], None] = lambda run: None) -> tuple[int, Summary | None]:
    """Run the scenario (three times with ``cfg.compare``) in a directory of its own; returns ``(status, summary)``.

    ``on_start`` gets each run's directory as its services start (a forced exit names it: :func:`forced_exit_note`).
    The summary's ``extra`` holds ``comparison`` (one row per planner: interference, contact, ...), ``verdict``
    (with ``--compare``), ``figure`` (the PNG) and ``run_dir``.
    """
    from services import demo_run
    from services.demo_figure import draw_outcomes, figure_title
    from services.demo_outcome import cut_words, measure_run, outcome_lines, verdict
    from shared.robot import PR2

    _check_models_dir(cfg)
    _check_live_port(cfg)
    scene = load_scene(cfg.scene or None)
    run_dir = RunDirectory.create(Path(cfg.run_dir), cfg.mode, cfg.compare)
    root = run_dir.path
    variants = VARIANTS if cfg.compare else ((_variant_name(cfg), {}),)
    records: list[RunRecord] = []
    status = 0
    try:
        for name, changes in variants:
            if cfg.compare:
                out(f"foresight demo: --- {name} ---")
            sub = dataclasses.replace(cfg, compare=False, **changes,
                                      run_dir=root / variant_dir(name) if cfg.compare else root)
            def started(run: Path = Path(sub.run_dir)) -> None:
                run_dir.point_latest()
                on_start(run)
            status, record = demo_run.run_once(sub, name, stop, out, started=started)
            if record is None:
                if records:  # interrupted before this planner's first plan: what the earlier ones did still counts
                    break
                return status or 1, None
            records.append(record)
            if status != 0:
                break
            if stop.is_set():  # Ctrl-C while this planner's services stopped: its run is whole, the next not begun
                if cfg.compare and len(records) < len(variants):
                    out(f"foresight demo: interrupted: the comparison stops after {name}")
                    status = 130
                break
    finally:
        if not records and not run_dir.has_log():  # a bad option found late, Ctrl-C while training or starting
            run_dir.end_without_log()
        if not records and status and (where := run_dir.whereabouts()):  # no summary will name the directory
            out(f"foresight demo: {where}")
    robot = PR2.from_scene(scene)
    reference = records[0].final  # the final prediction of the paper's method
    outcomes = [measure_run(r.name, r.states, r.poses, reference, robot, scene, r.summary) for r in records]
    summary = records[0].summary
    summary.extra["run_dir"] = str(root)
    summary.extra["comparison"] = [o.to_json() for o in outcomes]
    if cfg.compare and len(outcomes) == len(VARIANTS):
        summary.extra["verdict"] = verdict(outcomes)
    planned = [name for name, _ in variants]
    cut = cut_words(outcomes, planned, failed=status not in (0, 130))
    title = figure_title(cfg, summary, scene.name, cut)
    against = ("the prediction planner's final prediction" if summary.scored_against == "final prediction"
               else f"the run's {summary.scored_against}")
    summary.extra["outcome_lines"] = outcome_lines(outcomes, against, planned, failed=status not in (0, 130))
    figure = picture(lambda png: draw_outcomes(outcomes, scene, reference, records[0].poses, png, cfg.period_s,
                                                title), root / "run.png", out)
    if figure is not None:
        summary.extra["figure"] = str(figure)
    return status, summary


def _variant_name(cfg: DemoConfig) -> str:
    """The planner a single run uses, named as in :data:`VARIANTS`."""
    if not cfg.human_cost:
        return "no human cost"
    return "prediction" if cfg.method == "prediction" else "current occupancy"


def _bare_live(argv: list[str]) -> list[str]:
    """``--live`` without a port means Foxglove's default port (8765).

    "Without a port": last, or followed by another option (``--...``). Anything else after it is its value, checked
    as one (``--live -1`` and ``--live abc`` are one-line errors, not a stray argument).
    """
    out = []
    for i, a in enumerate(argv):
        out.append(a)
        if a == "--live" and (i + 1 == len(argv) or argv[i + 1].startswith("--")):
            out.append(str(LIVE_PORT))
    return out


LIVE_PORT = DEFAULT_PORT
"""``foresight demo --live``'s port without a number: the Foxglove app's default."""


def main(argv: list[str] | None = None, prog: str = "foresight demo") -> int:
    """Run the demo; returns its exit status (0: a whole run; the others in this module's docstring)."""
    parser = ArgumentParser(prog=prog, description=help_text(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_arguments(parser, "demo", DemoConfig, with_zenoh=False)
    args = parser.parse_args(_bare_live(sys.argv[1:] if argv is None else list(argv)))
    with cli_errors(prog):
        cfg, _ = resolve_config("demo", DemoConfig, args, with_zenoh=False)
        check_inputs(cfg)  # a misspelt class, scene or library: said now, not after the imports below (8-10 s)
        # the services inherit the environment and the file: a misspelt name or bad value of any of them is an error
        # now, not later (each section's variables are checked as it is resolved)
        share_config_file(args.config, cfg)
        setup_logging(cfg.log_level)
        stop = threading.Event()
        runs: list[Path] = []  # whose services started: a forced exit names the last (they stop on their own)
        restore = stop_on_signals(stop, grace_s=STOP_GRACE_S, prog=prog,  # the services' own bounded stops come first
                                  context=lambda: forced_exit_note(runs[-1]) if runs else None)
        progress = (lambda line: print(line, file=sys.stderr, flush=True)) if cfg.json else \
            (lambda line: print(line, flush=True))
        if cfg.prepare is not None:
            from services.demo_prepare import prepare_or_stop

            try:
                return prepare_or_stop(cfg, cfg.prepare, stop, progress)
            finally:
                restore()
        try:
            status, summary = run_demo(cfg, stop, out=progress, on_start=runs.append)
        finally:
            restore()
        if summary is not None:
            if cfg.json:
                print(strict_json.dumps(summary.to_json()))
            else:
                for line in closing_lines(cfg, summary, interrupted=status == 130):
                    print(line)
        return status


if __name__ == "__main__":
    sys.exit(main())
