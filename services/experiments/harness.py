"""One lock-step run of the whole system, in-process: the four services over loopback Zenoh.

The experiments do not re-implement the loop: each run starts the real replayer, predictor, planner
and executor services (each with its own Zenoh session, connected to a hub session of this process
that listens on a free loopback port, multicast scouting off), lets the executor tick the run, and
records every message the services publish, as the wire carries it. The planner is built once per
configuration and handed to each run (:meth:`Planner.reset` with the run's seed), so a run costs its
planning, not the IK of its goals.
"""

from __future__ import annotations

import hashlib
import logging
import pickle
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from services.executor.config import lockstep_stale_limit
from services.executor.core import ExecutorConfig
from services.executor.service import ExecutorResult, ExecutorService, load_models
from services.planner.core import Planner
from services.planner.service import PlannerService, PlannerServiceConfig
from services.predictor.core import PredictorConfig
from services.predictor.service import PredictorService
from services.processes import free_port
from services.replayer.core import ReplayerConfig
from services.replayer.service import ReplayerService
from shared.config import ZenohConfig
from shared.protocol import ClassPosterior, HumanPose, Keys, Message, OccupancyGrid, Plan, RobotState
from shared.scene import Scene
from shared.transport import open_session, subscribe

__all__ = ["RunSpec", "RunRecord", "ServiceThread", "run_lockstep", "RunFailed", "PlanningFailed", "LateInputs",
           "ServiceFailed", "JOIN_S"]

log = logging.getLogger("foresight.experiments")

JOIN_S = 60.0
"""Longest wait (s) for a service thread to stop."""
SETTLE_QUIET_S = 0.1
"""A run's messages are all in once none came for this long after the executor's last (and its states are in)."""
SETTLE_LIMIT_S = 2.0
"""Longest wait (s) for a run's last messages after the executor's end (``_Collector.settle``)."""


@dataclass(frozen=True)
class RunSpec:
    """What one lock-step run is.

    Attributes:
        scene: The scene every service loads.
        model: Prediction model file (trained without the streamed demonstration).
        human: Library file holding the one demonstration the replayer streams.
        samples_per_tick: Poses per replanning step (the human advances by a fixed amount per step).
        method: The predictor's occupancy: ``"prediction"`` or ``"current"``.
        steps: Replanning steps (the paper: 20).
        period_s: Simulated seconds per step.
        seed: STOMP seed of the run.
        timeout_s: Longest wall time of the run.
        path_per_step: The executor's pace: configuration-space length per step (0: the plan's timing);
            ``path_weights`` its per-joint weights; ``finish_path``: the rest of the path after the last step
            (``ExecutorConfig``; the paper protocol, :mod:`services.experiments.protocol`).
        evidence: The predictor's posterior: ``sum`` or ``mean`` (``PredictorConfig.evidence``);
            ``temperature``: its temperature (0: the model file's).
    """

    scene: Scene
    model: Path
    human: Path
    samples_per_tick: int
    method: str = "prediction"
    steps: int = 20
    period_s: float = 0.2
    seed: int = 0
    timeout_s: float = 300.0
    path_per_step: float = 0.0
    path_weights: tuple[float, ...] = ()
    finish_path: bool = False
    evidence: str = "sum"
    temperature: float = 0.0


@dataclass
class RunRecord:
    """Everything a run published, as received over Zenoh.

    Attributes:
        plans: One Plan per step, in tick order.
        states: Executed RobotStates, in time order.
        poses: The streamed HumanPoses, in time order.
        occupancy: The final grid (``tick_last``) of each tick, by tick.
        posteriors: The last ClassPosterior of each tick, by tick.
        result: The executor's own account of the run.
    """

    plans: list[Plan] = field(default_factory=list)
    states: list[RobotState] = field(default_factory=list)
    poses: list[HumanPose] = field(default_factory=list)
    occupancy: dict[int, OccupancyGrid] = field(default_factory=dict)
    posteriors: dict[int, ClassPosterior] = field(default_factory=dict)
    result: ExecutorResult | None = None

    @property
    def final_occupancy(self) -> OccupancyGrid | None:
        """The grid of the last tick (the most accurate prediction of the run)."""
        return self.occupancy[max(self.occupancy)] if self.occupancy else None

    def q(self) -> np.ndarray:
        """``(N, D)`` executed configurations."""
        return np.array([s.q for s in self.states])

    def stamps(self) -> np.ndarray:
        """``(N,)`` their times (s)."""
        return np.array([s.stamp for s in self.states])

    def chosen_goals(self) -> list[str]:
        """The goal chosen at each step."""
        return [p.goal_names[p.chosen] for p in self.plans]


class _Collector:
    """Thread-safe sink of the messages of a run (fed by Zenoh subscriber threads)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.arrived = threading.Condition(self.lock)
        self.plans: dict[int, Plan] = {}
        self.record = RunRecord()
        self.last_at = time.monotonic()

    def __call__(self, msg: Message) -> None:
        with self.lock:
            self.last_at = time.monotonic()
            self.arrived.notify_all()
            rec = self.record
            if isinstance(msg, Plan):
                self.plans[msg.tick] = msg
            elif isinstance(msg, RobotState):
                rec.states.append(msg)
            elif isinstance(msg, HumanPose):
                rec.poses.append(msg)
            elif isinstance(msg, OccupancyGrid):
                if msg.tick_last:
                    rec.occupancy[msg.tick] = msg
            elif isinstance(msg, ClassPosterior):
                rec.posteriors[msg.tick] = msg

    def settle(self, result: ExecutorResult, quiet_s: float = SETTLE_QUIET_S, limit_s: float = SETTLE_LIMIT_S) -> None:
        """Wait until the run's last messages are in (at most ``limit_s``).

        In: every state the executor published, the final grid of the newest tick a pose came for, and then
        ``quiet_s`` without a message (the executor lingers only for a log of its own).
        """
        n_states = len(result.times)

        def missing() -> str:
            rec = self.record
            ticks = [p.tick for p in rec.poses]
            gaps = [f"{len(rec.states)} of {n_states} robot states"] if len(rec.states) < n_states else []
            return ", ".join(gaps + ([f"no final grid of tick {max(ticks)}"]
                                     if ticks and max(ticks) not in rec.occupancy else []))

        deadline = time.monotonic() + limit_s
        with self.lock:
            while missing() or time.monotonic() - self.last_at < quiet_s:
                if (left := deadline - time.monotonic()) <= 0:
                    break
                self.arrived.wait(min(left, quiet_s))
            if gap := missing():
                log.warning("experiments: the run's last messages were not all in after %.1f s (%s); measuring what "
                            "came", limit_s, gap)

    def finish(self, result: ExecutorResult | None) -> RunRecord:
        with self.lock:
            rec = self.record
            rec.plans = [self.plans[t] for t in sorted(self.plans)]
            rec.states.sort(key=lambda s: s.stamp)
            rec.poses.sort(key=lambda p: (p.stamp, p.index))
            rec.result = result
            return rec


class ServiceThread:
    """Runs a service's blocking ``run(stop)`` in a daemon thread with its own stop event."""

    def __init__(self, name: str, target: Callable[[threading.Event], Any],
                 stop_event: threading.Event | None = None) -> None:
        self.name = name
        self.stop_event = stop_event or threading.Event()
        self.result: Any = None
        self.error: BaseException | None = None

        def body() -> None:
            try:
                self.result = target(self.stop_event)
            except BaseException as exc:  # re-raised by join()
                self.error = exc

        self.thread = threading.Thread(target=body, name=f"svc-{name}", daemon=True)

    def start(self) -> ServiceThread:
        """Start the thread."""
        self.thread.start()
        return self

    def stop(self, timeout: float = JOIN_S) -> Any:
        """Ask the service to stop and wait for it (see :meth:`join`)."""
        self.stop_event.set()
        return self.join(timeout)

    def join(self, timeout: float = JOIN_S) -> Any:
        """Wait for the service; its result, or its exception re-raised.

        Raises:
            TimeoutError: If it is still running after ``timeout`` seconds.
        """
        self.thread.join(timeout)
        if self.thread.is_alive():
            raise TimeoutError(f"{self.name} did not stop within {timeout:g} s")
        if self.error is not None:
            raise self.error
        return self.result


class RunFailed(RuntimeError):
    """A lock-step run that is no measurement (its numbers would be those of a broken run, or depend on timing)."""


class PlanningFailed(RunFailed):
    """A lock-step run's planner failed a step: the run measures a robot without plans, so it is no measurement."""


class LateInputs(RunFailed):
    """A lock-step wait ran out and the run went on without a plan, prediction or state.

    Its numbers depend on timing (one late grid gave another path), so the run is refused rather than scored.
    """


class ServiceFailed(RunFailed):
    """A service of the run ended with an error while the executor still ran (its exception is the cause)."""


def _join_unless_run_fails(threads: list[ServiceThread], planner: PlannerService, timeout_s: float) -> Any:
    """The executor's (the last thread's) result once it ends; at once a :class:`RunFailed` if the run fails.

    Without it a failed planner step, or a service that died (a torch error in the planner), left the executor
    waiting ``lockstep_timeout_s`` for each tick's plan: the run was measured as if the robot had stood still on
    purpose, or ended minutes later in a TimeoutError that named none of the causes.

    Raises:
        PlanningFailed: A planner step failed. ServiceFailed: A service ended with an error (chained).
        LateInputs: A lock-step wait ran out (the executor's or the planner's). TimeoutError: The run overran.
    """
    *others, executor = threads
    deadline = time.monotonic() + timeout_s

    def dead() -> ServiceThread | None:
        return next((t for t in others if t.error is not None), None)

    while (executor.thread.is_alive() and not planner.stats.failures and dead() is None
           and time.monotonic() < deadline):
        executor.thread.join(0.05)
    if planner.stats.failures:
        raise PlanningFailed(f"the planner failed {planner.stats.failures} step(s) of the run "
                             f"({planner.stats.plans} planned); last: {planner.stats.last_error}")
    if executor.thread.is_alive() and (failed := dead()) is not None:
        raise ServiceFailed(f"the {failed.name} failed during the run: {type(failed.error).__name__}: "
                            f"{failed.error}") from failed.error
    if executor.thread.is_alive():
        raise TimeoutError(f"{executor.name} did not stop within {timeout_s:g} s")
    result = executor.join(0)
    if result.lockstep_timeouts or planner.stats.late_inputs:
        last = f"; {planner.stats.last_late}" if planner.stats.last_late else ""
        raise LateInputs(f"lock-step waits ran out: the executor went on without a plan or prediction "
                         f"{result.lockstep_timeouts} time(s), the planner planned {planner.stats.late_inputs} "
                         f"tick(s) without its inputs{last} (a run whose numbers depend on timing is no measurement)")
    return result


_EXECUTOR_MODELS: OrderedDict[tuple[str, str], tuple[Any, Any]] = OrderedDict()
EXECUTOR_MODELS_KEPT = 4
"""Scenes whose executor models are kept (the least recently used goes): an experiment runs one or two."""


def _executor_models(scene: Scene) -> tuple[Any, Any]:
    """The executor's robot and human models for ``scene``, loaded once per scene (runs are sequential).

    Keyed by the scene's reference and content, not the object: every experiment loads its scene again, and a pace
    sweep kept one robot model per point (keyed by ``id``, which a later scene can reuse).
    """
    key = (scene.ref, hashlib.sha256(pickle.dumps(scene)).hexdigest())
    if key not in _EXECUTOR_MODELS:
        robot, human, place = load_models(scene)
        _EXECUTOR_MODELS[key] = (robot, (human, place))
        while len(_EXECUTOR_MODELS) > EXECUTOR_MODELS_KEPT:
            _EXECUTOR_MODELS.popitem(last=False)
    _EXECUTOR_MODELS.move_to_end(key)
    return _EXECUTOR_MODELS[key]


def run_lockstep(spec: RunSpec, planner: Planner, mcap: str | Path | None = None) -> RunRecord:
    """Run the four services in lock-step for ``spec.steps`` steps and record what they publish.

    Args:
        spec: The run.
        planner: A planner for ``spec.scene`` (reset here with ``spec.seed``; reused across runs); the
            planner service runs it in lock-step with its ``config``.
        mcap: MCAP log of the run (None: no log).

    Returns:
        The run's messages and the executor's result.

    Raises:
        TimeoutError: If the run or a service's shutdown overran its time limit.
        PlanningFailed: If a planner step failed (bad input or no plan), as soon as it did.
    """
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hub = ZenohConfig(mode="peer", listen=[endpoint], connect=[], multicast_scouting=False)
    peer = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], multicast_scouting=False)
    keys = Keys(hub.prefix)
    collect = _Collector()
    planner.reset(seed=spec.seed)
    scene_ref = spec.scene.ref
    svc_cfg = PlannerServiceConfig(mode="lockstep", period_s=spec.period_s, input_timeout_s=min(60.0, spec.timeout_s),
                                   scene=scene_ref, planner=planner.config)
    predictor = PredictorService(PredictorConfig(model=spec.model, method=spec.method, scene=scene_ref,
                                                 evidence=spec.evidence, temperature=spec.temperature), peer)
    planner_svc = PlannerService(svc_cfg, peer, planner=planner, scene=spec.scene)
    replayer = ReplayerService(ReplayerConfig(library=spec.human, mode="lockstep",
                                              samples_per_tick=spec.samples_per_tick), peer)
    ex_stop = threading.Event()
    robot, human = _executor_models(spec.scene)
    ex_cfg = ExecutorConfig(mode="lockstep", steps=spec.steps, step_period_s=spec.period_s,
                            mcap=str(mcap) if mcap else "none", scene=scene_ref,
                            lockstep_timeout_s=min(60.0, spec.timeout_s), path_per_step=spec.path_per_step,
                            path_weights=list(spec.path_weights), finish_path=spec.finish_path)
    ex_cfg = replace(ex_cfg, stale_limit_s=lockstep_stale_limit(spec.period_s, ex_cfg.stale_limit_s))
    executor = ExecutorService(ex_cfg, peer, stop=ex_stop, robot=robot, human=human, scene=spec.scene)
    threads = [ServiceThread("predictor", predictor.run), ServiceThread("planner", planner_svc.run),
               ServiceThread("replayer", replayer.run),
               ServiceThread("executor", lambda _stop: executor.run(), stop_event=ex_stop)]
    result: ExecutorResult | None = None
    with open_session(hub) as session:
        subs = [subscribe(session, key, cls, collect) for key, cls in
                ((keys.plan, Plan), (keys.robot_state, RobotState), (keys.occupancy, OccupancyGrid),
                 (keys.posterior, ClassPosterior), (keys.pose, HumanPose))]
        try:
            for t in threads:
                t.start()
            result = _join_unless_run_fails(threads, planner_svc, spec.timeout_s)
            collect.settle(result)  # the executor, with no log of its own to fill, does not linger
        except BaseException as exc:
            failed: BaseException | None = exc
            raise
        else:
            failed = None
        finally:
            for t in threads:
                t.stop_event.set()
            errors = []
            for t in threads:
                try:
                    t.join(JOIN_S)
                except Exception as exc:  # report the first after stopping all
                    errors.append(exc)
                    if failed is not None and exc not in (failed, failed.__cause__):  # lost with the run's error
                        log.error("stopping the failed run's %s: %s: %s", t.name, type(exc).__name__, exc)
            for s in subs:
                s.undeclare()
        if errors:
            raise errors[0]
    return collect.finish(result)
