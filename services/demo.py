"""``foresight demo`` (``make demo``): the two-cup scenario with the four services as processes.

1. Load the motion library (default: the embedded synthetic one) and pick the demonstration the human
   performs (a reach for the red cup unless ``--human-class`` says otherwise).
2. Train the prediction model without that demonstration, unless it is cached in ``models/``.
3. Be the Zenoh router on a free loopback port and start the replayer, predictor, planner and
   executor, each as ``python -m services.<name> --connect <router>`` (logs in ``runs/demo/``).
4. Lock-step (default): the executor ticks ``--steps`` replanning steps; the human advances by a fixed
   number of samples per step (the paper's protocol). Real time: the replayer streams at ``--rate-hz``,
   the planner replans every ``--period-s``, the executor runs ``steps x period`` seconds.
   While it runs, print one table: a header, then a row per replanning step as its plan arrives
   (step, seconds into the run, chosen goal, each candidate's cost, planning time, the predictor's
   belief); in real time only the plans made during the executor's ``steps x period`` seconds.
5. Stop everything (SIGTERM, then SIGKILL after a bounded wait) and print the summary: the step where
   the robot switched goal, the step and time it reached it, the interference cost of the executed
   trajectory against the final prediction, the MCAP path.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import threading
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from services.experiments.measures import interference
from services.processes import ServiceProcess, free_port
from services.scenario import (
    RunRecorder,
    Summary,
    choose_demonstration,
    model_for,
    step_entry,
    summarise,
    table_header,
    table_row,
)
from services.supervisor import Supervisor
from shared.config import ConfigError, ZenohConfig, add_config_arguments, opt, resolve_config
from shared.feature_sets import LIVE_MAPPING, require_mapping
from shared.library import MotionLibrary, load_library, save_library
from shared.protocol import ClassPosterior, Keys, Message, OccupancyGrid, Plan, RobotState
from shared.runtime import cli_errors, help_text, setup_logging, stop_on_signals
from shared.scene import Scene, load_scene
from shared.transport import Presence, open_session, subscribe

__all__ = ["DemoConfig", "run_demo", "main", "SERVICES_IN_ORDER"]

log = logging.getLogger("foresight.demo")

SERVICES_IN_ORDER = ("predictor", "planner", "replayer", "executor")
"""Start order: the executor (simulation master) last, once the others listen."""

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
    human_class: str = opt("", help="class (name or index) the human performs (default: red_cup, else the last)")
    scene: str = opt("", help="scene: an embedded name (pr2_two_cups, pr2_two_cups_facing, pr2_two_cups_side, or the "
                     "paper's PR2TwoCups, PR2TwoCupsFacing, PR2TwoCupsSide) or a scene TOML file (empty: pr2_two_cups)")
    method: str = opt("prediction", choices=("prediction", "current"),
                      help="occupancy the planner avoids: the early prediction, or the current posture only")
    human_cost: bool = opt(True, help="plan with the human-penetration cost (off: the paper's 'basic STOMP')")
    compare: bool = opt(False, help="run the scenario three times (prediction, current occupancy, no human cost) "
                        "and compare their interference with the final prediction (the paper's Table I)")
    components: int = opt(-1, help="Gaussians per class when training (-1: the trainer's default, 20)")
    robot_speed: float = opt(0.25, help="fraction of the PR2's joint velocity limits the planner times trajectories "
                             "with (a collaborative speed; the planner's --velocity-scale)")
    period_s: float = opt(0.2, help="replanning period (simulated s per step in lock-step, wall s in real time)")
    rate_hz: float = opt(30.0, help="real time: poses per second")
    models_dir: Path = opt(Path("models"), help="where trained models are cached")
    run_dir: Path = opt(Path("runs/demo"), help="service logs and the MCAP file go here")
    port: int = opt(0, help="loopback TCP port of the demo's Zenoh router (0 = a free port)")
    prefix: str = opt("foresight", help="key-expression prefix")
    timeout: float = opt(900.0, help="give up after this many seconds")
    restart: bool = opt(False, help="start a service that dies during the run again (at most 3 times); without "
                        "it the run carries on without the service (the executor holds the robot)")
    json: bool = opt(False, help="print one JSON object with the summary (progress goes to stderr)")
    log_level: str = opt("WARNING", choices=("DEBUG", "INFO", "WARNING", "ERROR"), help="log level of the demo")

    def validate(self) -> None:
        """Check value ranges."""
        if self.steps < 1:
            raise ConfigError(f"demo.steps: must be >= 1, got {self.steps}")
        if not (self.period_s > 0 and self.rate_hz > 0 and self.timeout > 0):
            raise ConfigError("demo.period_s, demo.rate_hz and demo.timeout must be > 0")
        if not 0 < self.robot_speed <= 1:
            raise ConfigError(f"demo.robot_speed: must be in (0, 1], got {self.robot_speed}")
        if not 0 <= self.port < 65536:
            raise ConfigError(f"demo.port: must be 0..65535, got {self.port}")


def _library(cfg: DemoConfig, scene: Scene) -> MotionLibrary:
    if cfg.library is None:
        from shared.synthetic import generate_library

        return generate_library(seed=0, scene=scene)  # its cup classes reach for this scene's cups
    lib = load_library(cfg.library)
    require_mapping(lib.feature_names, "foresight demo (HumanPose messages, occupancy)",
                    f"library {lib.source}", exact=LIVE_MAPPING)
    return lib


def service_args(cfg: DemoConfig, endpoint: str, model: Path, replay_library: Path, samples_per_tick: int,
                 mcap: Path) -> dict[str, list[str]]:
    """Command-line arguments of each service for this demo."""
    common = ["--connect", endpoint, "--listen", "tcp/127.0.0.1:0", "--prefix", cfg.prefix, "--zenoh-mode", "peer",
              "--log-level", "INFO"]
    scene = ["--scene", cfg.scene] if cfg.scene else []
    lockstep = cfg.mode == "lockstep"
    return {
        "predictor": ["--model", str(model), "--method", cfg.method, *scene, *common],
        "planner": ["--mode", cfg.mode, "--seed", str(cfg.seed), "--period-s", str(cfg.period_s),
                    "--velocity-scale", str(cfg.robot_speed),
                    "--lookahead-s", str(cfg.period_s), *([] if cfg.human_cost else ["--cost.w-human", "0"]), *scene,
                    *common],
        "replayer": ["--library", str(replay_library), "--mode", cfg.mode, "--samples-per-tick", str(samples_per_tick),
                     "--rate-hz", str(cfg.rate_hz), *([] if lockstep else ["--wait-for", "executor"]), *common],
        "executor": ["--mode", cfg.mode, "--steps", str(cfg.steps), "--step-period-s", str(cfg.period_s),
                     "--mcap", str(mcap), *scene, *common],
    }


def _belief(posterior: ClassPosterior | None) -> str:
    if posterior is None:
        return ""
    k = int(posterior.posterior.argmax())
    return f"{posterior.class_names[k]} p={posterior.posterior[k]:.2f}"


def _run_length(cfg: DemoConfig) -> str:
    if cfg.mode == "lockstep":
        return f"lockstep mode, {cfg.steps} steps of {cfg.period_s:g} s (simulated time)"
    return (f"realtime mode, {cfg.steps * cfg.period_s:g} s of wall time ({cfg.steps} periods of {cfg.period_s:g} s; "
            "a plan per period while the planner keeps up)")


VARIANTS = (("prediction", {"method": "prediction", "human_cost": True}),
            ("current occupancy", {"method": "current", "human_cost": True}),
            ("no human cost", {"method": "prediction", "human_cost": False}))
"""The planners ``--compare`` runs: the paper's method and its two baselines (Fig. 8/9, Table I)."""


def run_demo(cfg: DemoConfig, stop: threading.Event, out: Callable[[str], None] = print) -> tuple[int, Summary | None]:
    """Run the scenario (three times with ``cfg.compare``); returns ``(exit status, summary)``."""
    if not cfg.compare:
        status, summary, _ = _run_once(cfg, stop, out)
        return status, summary
    from shared.robot import PR2

    runs = []
    for name, changes in VARIANTS:
        out(f"foresight demo: --- {name} ---")
        sub = dataclasses.replace(cfg, compare=False, run_dir=Path(cfg.run_dir) / name.replace(" ", "-"), **changes)
        status, summary, record = _run_once(sub, stop, out)
        if status != 0 or summary is None:
            return status or 1, summary
        runs.append((name, summary, record))
    reference = runs[0][2][2]  # the final prediction of the paper's method
    robot = PR2.from_scene(load_scene(cfg.scene or None))
    rows = []
    for name, summary, (_, states, _, _) in runs:
        states = sorted(states, key=lambda st: st.stamp)
        q = np.array([st.q for st in states])
        cost = interference(robot, q, np.array([st.stamp for st in states]), reference) if reference else 0.0
        rows.append({"planner": name, "interference_cost": cost, "switch_step": summary.switch_step,
                     "reached_step": summary.reached_step, "chosen_goal_per_step": summary.chosen_goal_per_step,
                     "mcap_path": summary.mcap_path})
    main_summary = runs[0][1]
    main_summary.extra["comparison"] = rows
    return 0, main_summary


def _run_once(cfg: DemoConfig, stop: threading.Event, out: Callable[[str], None]
              ) -> tuple[int, Summary | None, tuple[Any, ...]]:
    """One run of the scenario; returns ``(exit status, summary, the recorder's snapshot)``."""
    scene = load_scene(cfg.scene or None)
    lib = _library(cfg, scene)
    scenario = choose_demonstration(lib, cfg.steps, cfg.seed, cfg.human_class)
    demo = scenario.demo
    out(f"foresight demo: library {lib.source}: {lib.n_classes} classes, {len(lib.demos)} demonstrations; "
        f"the human performs {demo.class_name} #{demo.index} ({demo.n_samples} samples, "
        f"{scenario.samples_per_tick} per step)")
    model = model_for(lib, scene, demo, cfg.models_dir, None if cfg.components < 0 else cfg.components)
    out(f"foresight demo: prediction model {model}")
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    replay_lib = run_dir / "human.npz"
    save_library(MotionLibrary(class_names=list(lib.class_names), demos=[demo], issues=[],
                               source=f"{lib.source} ({demo.class_name} #{demo.index})"), replay_lib)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    mcap = run_dir / f"{stamp}-{cfg.mode}.mcap"
    endpoint = f"tcp/127.0.0.1:{cfg.port or free_port()}"
    keys = Keys(cfg.prefix)
    args = service_args(cfg, endpoint, model, replay_lib, scenario.samples_per_tick, mcap)
    out(f"foresight demo: router on {endpoint}; {_run_length(cfg)}; logs in {run_dir}/")
    hub = ZenohConfig(mode="router", listen=[endpoint], connect=[], multicast_scouting=False, prefix=cfg.prefix)
    recorder = RunRecorder()
    latest_posterior: list[ClassPosterior | None] = [None]
    realtime = cfg.mode == "realtime"
    lock = threading.Lock()
    # the run's clock: 0 in lock-step (simulated time); the executor's first state in real time
    run_start: list[float | None] = [None if realtime else 0.0]
    header_printed = [False]

    def on_state(msg: RobotState) -> None:
        with lock:
            if run_start[0] is None:
                run_start[0] = msg.stamp
        recorder.on_message(msg)

    def on_plan(msg: Plan) -> None:
        with lock:
            if run_start[0] is None:
                run_start[0] = msg.stamp
            t0 = run_start[0]
            if realtime and msg.stamp - t0 >= cfg.steps * cfg.period_s:
                return  # planned after the executor's run ended: never executed, not part of the run
            recorder.on_message(msg)
            if not header_printed[0]:
                out(table_header(list(msg.goal_names)))
                header_printed[0] = True
            out(table_row(step_entry(msg, t0), list(msg.goal_names), _belief(latest_posterior[0])))

    def on_other(msg: Message) -> None:
        if isinstance(msg, ClassPosterior):
            latest_posterior[0] = msg
        recorder.on_message(msg)

    status = 0
    procs = {name: ServiceProcess(name, f"services.{name}", args[name], run_dir / f"{name}.log")
             for name in SERVICES_IN_ORDER}
    deadline = time.monotonic() + cfg.timeout
    with open_session(hub) as session:
        subs = [subscribe(session, keys.plan, Plan, on_plan),
                subscribe(session, keys.robot_state, RobotState, on_state),
                subscribe(session, keys.occupancy, OccupancyGrid, on_other),
                subscribe(session, keys.posterior, ClassPosterior, on_other)]
        presence = Presence(session, keys, "demo")
        try:
            for name in SERVICES_IN_ORDER:
                procs[name].start()
                if name != "executor":
                    procs[name].wait_alive(presence.is_alive, timeout=min(120.0, cfg.timeout))
            executor = procs["executor"]
            supervisor = Supervisor(procs, out, restart=cfg.restart)
            while not stop.is_set() and executor.running:
                if time.monotonic() > deadline:
                    out(f"foresight demo: timeout after {cfg.timeout:g} s")
                    status = 1
                    break
                supervisor.check()  # a dead service is reported (and restarted), the run goes on
                stop.wait(0.1)
            if stop.is_set():
                out("foresight demo: interrupted")
                status = 130
            elif executor.returncode not in (0, None):
                out(f"foresight demo: executor exited with status {executor.returncode}: {executor.tail(2)}")
                status = 1
            if supervisor.faults:
                out("foresight demo: faults during the run: " + ", ".join(
                    f"{name} ({'killed' if code is not None and code < 0 else code})"
                    for name, code in supervisor.faults))
        finally:
            for name in reversed(SERVICES_IN_ORDER):
                code = procs[name].stop(timeout=10.0)
                if code not in (0, None, -15):
                    log.warning("%s exited with status %s", name, code)
            presence.close()
            for s in subs:
                s.undeclare()
    plans, states, final, posteriors = recorder.snapshot()
    if not plans:
        out("foresight demo: no plan was received; see the service logs in " + str(run_dir))
        return 1, None, (plans, states, final, posteriors)
    from shared.robot import PR2

    summary = summarise(plans, states, final, posteriors, PR2.from_scene(scene), demo.class_name,
                        str(mcap) if mcap.is_file() else None, t0=run_start[0])
    summary.extra["mode"] = cfg.mode
    summary.extra["method"] = cfg.method
    summary.extra["human_cost"] = cfg.human_cost
    return status, summary, (plans, states, final, posteriors)


def main(argv: list[str] | None = None, prog: str = "foresight demo") -> int:
    """Run the demo; returns 0 when the run completed."""
    parser = argparse.ArgumentParser(prog=prog, description=help_text(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_arguments(parser, "demo", DemoConfig, with_zenoh=False)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, _ = resolve_config("demo", DemoConfig, args, with_zenoh=False)
        setup_logging(cfg.log_level)
        stop = threading.Event()
        restore = stop_on_signals(stop, grace_s=STOP_GRACE_S)  # the services' own bounded stops come first
        progress = (lambda line: print(line, file=sys.stderr, flush=True)) if cfg.json else \
            (lambda line: print(line, flush=True))
        try:
            status, summary = run_demo(cfg, stop, out=progress)
        finally:
            restore()
        if summary is not None:
            if cfg.json:
                print(json.dumps(summary.to_json()))
            else:
                for line in summary.lines(table=False):  # the table was printed live, row by row
                    print(line)
        return status


if __name__ == "__main__":
    sys.exit(main())
