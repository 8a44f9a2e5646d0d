"""One run of the demo's scenario: the four services as processes around a Zenoh router, watched and stopped.

:func:`run_once` trains (or loads) the prediction model, starts the predictor, planner, replayer and
executor (in that order, each in its own process group: :class:`services.processes.ServiceProcess`),
prints the table of plans as they arrive, supervises the services (:class:`services.supervisor.Supervisor`),
and on the executor's end or a stop request stops them, the executor first (it closes the MCAP).
:mod:`services.demo` runs it once or once per planner (``--compare``) and measures the outcome.
"""

from __future__ import annotations

import dataclasses
import logging
import shutil
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from services.demo_dirs import log_incomplete
from services.demo_inputs import check_goals, library_for
from services.demo_lines import Lines, log_phrase, unexecuted
from services.demo_services import (
    KEYPOINT_REST_S,
    KEYPOINTS_FILE,
    MODULES,
    extra_services,
    service_args,
    services_in_order,
)
from services.demo_status import ending, stop_in_order
from services.executor.result import INCOMPLETE, LOG_INCOMPLETE
from services.processes import ServiceProcess, free_port
from services.run_log import RunRecorder, keep_posterior, recorder_from_log
from services.run_table import step_entry, table_header, table_row
from services.scenario import (
    Scenario,
    Summary,
    belief,
    choose_demonstration,
    model_for,
    posterior_for,
    summarise,
)
from services.supervisor import Supervisor
from shared.config import ZenohConfig
from shared.library import MotionLibrary, save_library
from shared.progress import close_interrupted
from shared.protocol import ClassPosterior, HumanPose, Keys, Message, OccupancyGrid, Plan, RobotState
from shared.runtime import SHUTDOWN_GRACE_S, UserError, interruptible
from shared.scene import Scene, load_scene
from shared.security import secure_endpoints
from shared.transport import Presence, open_session, subscribe

if TYPE_CHECKING:
    from services.demo import DemoConfig

__all__ = ["RunRecord", "run_once", "prepare_inputs"]

log = logging.getLogger("foresight.demo")


def _run_length(cfg: DemoConfig) -> str:
    if cfg.mode == "lockstep":
        return f"lockstep mode, {cfg.steps} steps of {cfg.period_s:g} s (simulated time)"
    return (f"realtime mode, {cfg.run_s:g} s of wall time ({cfg.steps} periods of {cfg.period_s:g} s)"
            + (f" and on until the robot arrives, at most {cfg.finish_s:g} s more" if cfg.finish_s else "")
            + "; the planner replans as soon as it is idle and a new prediction has come, at least once a period: one "
            "row per plan")


@dataclasses.dataclass
class RunRecord:
    """What one run of the scenario left: its summary, what was received, and its measured outcome."""

    name: str
    summary: Summary
    states: list[RobotState]
    final: OccupancyGrid | None
    poses: list[HumanPose]
    run_dir: Path


def prepare_inputs(cfg: DemoConfig, scene: Scene, directory: Path, out: Callable[[str], None]
                   ) -> tuple[Scenario, Path, Path]:
    """The scenario's inputs: ``(scenario, model, human)``.

    The library, the human's demonstration (``directory/human.npz``, a library of one) and the prediction model
    trained without it (cached in ``cfg.models_dir``).
    """
    check_goals(cfg, scene)
    lib = library_for(cfg, scene)
    scenario = choose_demonstration(lib, cfg.steps, cfg.seed, cfg.human_class)
    demo = scenario.demo
    out(f"foresight demo: library {lib.source}: {lib.n_classes} classes, {len(lib.demos)} demonstrations; "
        f"the human performs {demo.class_name} #{demo.index} ({demo.n_samples} samples, "  # real time: its rate
        + (f"{scenario.samples_per_tick} per step)" if cfg.mode == "lockstep" else f"played at {cfg.rate_hz:g} Hz)"))
    # the tracker's keypoints: the novelty threshold calibrated for their noise, the mixtures' time from where its
    # reach rule starts a demonstration (the replayer's features: as recorded, from their first sample)
    noise = cfg.keypoint_noise_m if cfg.human == "keypoints" else 0.0
    model = model_for(lib, scene, demo, cfg.models_dir, None if cfg.components < 0 else cfg.components,
                      sensor_noise_m=noise, time_from="tracker" if cfg.human == "keypoints" else "recording",
                      on_train=lambda path: out(f"foresight demo: training the prediction model without the human's "
                                                f"demonstration, once: about a minute on 2 cores (its progress below); "
                                                f"later runs load it from {path.parent}"))
    out(f"foresight demo: prediction model {model}" + (f" (its novelty threshold calibrated for the keypoints' "
                                                        f"{noise * 100:g} cm of noise)" if noise else ""))
    directory.mkdir(parents=True, exist_ok=True)
    human = directory / "human.npz"
    one = MotionLibrary(class_names=list(lib.class_names), demos=[demo], issues=[],
                        source=f"{lib.source} ({demo.class_name} #{demo.index})")
    save_library(one, human)
    if cfg.human == "keypoints":  # the same demonstration as a sensor would see it, for the tracker to play
        import numpy as np

        from shared.keypoints.library import write_keypoint_library

        # the person stands still before and after the reach (the tracker learns the rest position, the reach ends);
        # written into the recording, so that the sensor's noise goes on through the rest as it would
        rest = round(KEYPOINT_REST_S * cfg.rate_hz)
        padded = np.concatenate([np.repeat(demo.features[:1], rest, 0), demo.features,
                                 np.repeat(demo.features[-1:], rest, 0)])
        seen = dataclasses.replace(one, demos=[dataclasses.replace(demo, features=padded)])
        for path in write_keypoint_library(seen, directory / "keypoints", noise_m=cfg.keypoint_noise_m, seed=cfg.seed):
            if path.stem == demo.class_name:  # the one class with a demonstration; the other files are empty
                path.replace(directory / KEYPOINTS_FILE)
            else:
                path.unlink()
        shutil.rmtree(directory / "keypoints")  # what is left: the class order of a library of one
        noise = f", noise {cfg.keypoint_noise_m * 100:g} cm per axis" if cfg.keypoint_noise_m else ""
        out(f"foresight demo: the human as body keypoints{noise}: {directory / KEYPOINTS_FILE} (foresight tracker "
            "--from fits the posture features back)")
    return scenario, model, human


def run_once(cfg: DemoConfig, planner: str, stop: threading.Event, out: Callable[[str], None],
             started: Callable[[], None] | None = None) -> tuple[int, RunRecord | None]:
    """One run of the scenario in ``cfg.run_dir``; returns ``(exit status, its record or None)``.

    ``started`` is called once its inputs are ready, as its services are about to start.
    """
    scene = load_scene(cfg.scene or None)
    run_dir = Path(cfg.run_dir)
    if stop.is_set():  # Ctrl-C during the imports: preparing (loading or training the model) went on for 6 s or more
        out("foresight demo: interrupted before the run was prepared; no service had started, nothing was recorded")
        return 130, None
    try:
        with interruptible(stop):  # training checks no stop event: Ctrl-C cuts it short at once
            scenario, model, replay_lib = prepare_inputs(cfg, scene, run_dir, out)
    except KeyboardInterrupt as exc:
        close_interrupted(exc)  # the training's progress bar ends before this line, not after it
        out("foresight demo: interrupted while preparing the run (a model cut short is not written); "
            "no service had started, nothing was recorded")
        return 130, None
    demo = scenario.demo
    if stop.is_set():
        out("foresight demo: interrupted before the services started; nothing was recorded")
        return 130, None
    if started is not None:
        started()
    mcap = run_dir / f"{run_dir.name}.mcap"
    endpoint = f"tcp/127.0.0.1:{cfg.port or free_port()}"
    keys = Keys(cfg.prefix)
    args = service_args(cfg, endpoint, model, replay_lib, scenario.samples_per_tick, mcap)
    hub = ZenohConfig(mode="router", listen=[endpoint], connect=[], multicast_scouting=False, prefix=cfg.prefix,
                      security_dir=str(cfg.security or ""), role="router")
    shown = secure_endpoints([endpoint])[0] if cfg.security else endpoint
    out(f"foresight demo: router on {shown}{' (mutual TLS, access control)' if cfg.security else ''}; "
        f"{_run_length(cfg)}; logs in {run_dir}/")
    recorder = RunRecorder()
    posteriors: dict[int, ClassPosterior] = {}  # the last of each tick (real time: every one, run_log.keep_posterior)
    realtime = cfg.mode == "realtime"
    lock = threading.Lock()
    # the run's clock: 0 in lock-step (simulated time); the executor's first state in real time
    run_start: list[float | None] = [None if realtime else 0.0]
    header_printed = [False]

    # the run is what the executor logged: after Ctrl-C it stops (closing the log) first while the others still
    # run, and what came later made the summary's rows and final prediction differ from the log's
    recording = threading.Event()
    recording.set()
    run_s = cfg.run_s + cfg.finish_s  # the longest a real-time run lasts

    def on_state(msg: RobotState) -> None:
        if not recording.is_set():
            return
        with lock:
            if run_start[0] is None:
                run_start[0] = msg.stamp
        recorder.on_message(msg)

    def on_plan(msg: Plan) -> None:
        if stop.is_set() or not recording.is_set():  # no row after Ctrl-C: the rows stop where the person did
            return
        with lock:
            if run_start[0] is None:
                run_start[0] = msg.stamp
            t0 = run_start[0]
            if realtime and msg.stamp - t0 >= run_s:
                return  # planned after the executor's run ended: never executed, not part of the run
            recorder.on_message(msg)
            if not header_printed[0]:
                out(table_header(list(msg.goal_names), "plan" if realtime else "step"))
                header_printed[0] = True
            # the belief the plan was made with, as the summary, `foresight log table` and --json give it (whichever
            # posterior came last made the live column differ from them, and from run to run)
            out(table_row(step_entry(msg, t0), list(msg.goal_names), belief(posterior_for(msg, posteriors))))

    def on_other(msg: Message) -> None:
        if not recording.is_set():
            return
        if isinstance(msg, ClassPosterior):
            with lock:
                keep_posterior(posteriors, msg)
        recorder.on_message(msg)

    status, whole = 0, False
    faults: list[str] = []
    # with --ros2 the ROS 2 gateway starts before the executor, so that it sees the whole run; so does the robot
    services = services_in_order(cfg)
    order = (*services[:-1], *extra_services(cfg), services[-1])
    procs = {name: ServiceProcess(name, MODULES.get(name, f"services.{name}"), args[name], run_dir / f"{name}.log")
             for name in order}
    deadline = time.monotonic() + cfg.timeout
    direct = out
    with Lines(direct) as out, open_session(hub) as session:  # the rows are printed on a thread of their own
        subs = [subscribe(session, keys.plan, Plan, on_plan),
                subscribe(session, keys.robot_state, RobotState, on_state),
                subscribe(session, keys.occupancy, OccupancyGrid, on_other),
                subscribe(session, keys.posterior, ClassPosterior, on_other),
                subscribe(session, keys.pose, HumanPose, on_other)]
        presence = Presence(session, keys, "demo")
        supervisor: Supervisor | None = None
        executor: ServiceProcess | None = None
        reported: set[str] = set()  # services whose end was said in a line: not again as a warning
        try:
            out(f"foresight demo: starting {', '.join(order)}")
            for name in order:
                if stop.is_set():
                    break
                procs[name].start()
                if name == "executor" and cfg.live:  # it serves the scene it logs
                    out(f"foresight demo: watch live at ws://127.0.0.1:{cfg.live} (Foxglove: Open connection -> "
                        "Foxglove WebSocket; layout docs/foresight.foxglove.json)" + (
                            "; a lock-step run is over in seconds: --mode realtime is the one to watch"
                            if cfg.mode == "lockstep" else ""))
                elif name != "executor":
                    began = time.monotonic()  # each service said as it comes up: the start-up is silent otherwise
                    if name == "planner":  # its first start took 10-50 s, and said nothing (a new user's first hour)
                        out("foresight demo: waiting for the planner: it loads torch and compiles its cost, typically "
                            f"10-40 s on 2 cores (its log: {procs[name].log_path})")
                    try:
                        up = procs[name].wait_alive(presence.is_alive, timeout=min(120.0, cfg.timeout), stop=stop)
                    except UserError as exc:  # died at start: this run ends (status 1, as an executor's failure),
                        out(f"foresight demo: {exc}")  # and --compare keeps the runs before it (it ended them all,
                        status = 1  # status 2, the code of bad input)
                        reported.add(name)
                        break
                    if up:
                        out(f"foresight demo: {name} up ({time.monotonic() - began:.1f} s)")
            executor = procs["executor"]
            supervisor = Supervisor(procs, out, restart=cfg.restart, fatal=cfg.mode == "lockstep",
                                    is_alive=presence.is_alive)
            while not stop.is_set() and executor.running:
                if time.monotonic() > deadline:
                    out(f"foresight demo: timeout after {cfg.timeout:g} s")
                    status = 1
                    break
                supervisor.check()  # a dead service is reported (and restarted); in real time the run goes on
                if supervisor.fatal_fault is not None:
                    status = 1
                    break
                stop.wait(0.1)
            faults = [f"{name} ({'hung' if code is None else 'killed' if code < 0 else code})"
                      for name, code in supervisor.faults]
            status, whole = ending(status, stop.is_set(), executor, faults, out)
        finally:
            said = reported | ({name for name, _ in supervisor.faults} if supervisor is not None else set())
            if executor is not None and executor.returncode and (status == 1 or executor.returncode == LOG_INCOMPLETE):
                said.add("executor")  # reported above, or in the closing MCAP line (its log): not again as a warning
            # past its grace its stack dump is kept; all within one budget, inside the demo's own grace (a signal's)
            for name, code in stop_in_order(procs, tuple(reversed(order)), SHUTDOWN_GRACE_S + 2.0):
                if name == "executor":  # its log is closed: what the others still send is not the run's
                    recording.clear()
                if code not in (0, None, -15) and name not in said:
                    log.warning("%s exited with status %s", name, code)
            presence.close()
            for s in subs:
                s.undeclare()
    out = direct
    received = len(recorder.snapshot()[0])
    if status and not whole and mcap.is_file():  # cut short: the summary is of what the log holds, as log table's is
        recorder = recorder_from_log(mcap, keys) or recorder
    plans, states, final, posteriors = recorder.snapshot()
    from shared.robot import PR2

    summary = summarise(plans, states, final, posteriors, PR2.from_scene(scene), demo.class_name,
                        str(mcap) if mcap.is_file() else None, t0=run_start[0],
                        received=recorder.plan_arrivals()) if plans else None
    n = len(summary.steps) if summary is not None else 0  # the plans the executor adopted (services.adopted_plans)
    if realtime and (whole or not status) and n < received:  # rows are printed as plans come, before the last state
        out(f"foresight demo: {unexecuted(received - n)}")
    done = f"{n} of {cfg.steps} steps" if cfg.mode == "lockstep" else f"{n} plans"
    if status and not whole:  # interrupted, a dead service, the executor's own failure, a timeout: what the log holds
        out(f"foresight demo: {'interrupted' if status == 130 else 'stopped'} after {done}; "
            f"{log_phrase(mcap, keys.plan, received, n)}")
    elif status == 1:  # it went to its end, not whole (faults said above); an incomplete log: its closing line says
        out(f"foresight demo: the run went to its end, but it is not whole ({n} plans"
            + (f" for its {cfg.steps} steps" if cfg.mode == "lockstep" else "") + "; see above): exit status 1")
    elif stop.is_set():  # a signal while the services stopped, after the run's end: it ended whole
        out("foresight demo: interrupted while stopping the services, after the run had ended: nothing was lost")
    if summary is None:
        if status != 130:
            out("foresight demo: no plan was received; see the service logs in " + str(run_dir))
        return status or 1, None
    summary.extra["mode"] = cfg.mode
    summary.extra["method"] = cfg.method
    summary.extra["human_cost"] = cfg.human_cost
    summary.extra.update(log_incomplete(executor))  # a full disk cut its log short: the closing MCAP line says so
    if status and not whole:  # its numbers are of a part of the run: no comparison may take them for a whole one
        summary.extra["cut_short"] = f"{'interrupted' if status == 130 else 'stopped'} after {done}"
    elif faults:  # real time goes on without (or with a restarted) service: a run, but not one to compare
        summary.extra["cut_short"] = "faults during the run: " + ", ".join(faults)
    elif executor is not None and executor.returncode == INCOMPLETE:  # no fault seen: a service hung for a while
        summary.extra["cut_short"] = "some ticks went on without their plan or prediction"
    if faults:
        summary.extra["faults"] = faults
    return status, RunRecord(planner, summary, states, final, recorder.human_poses(), run_dir)


