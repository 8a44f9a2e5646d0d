"""The executor service: the simulation master of a run and its MCAP logger.

One Zenoh subscriber on ``<prefix>/**`` receives every message of the run (its own included): each
payload is logged (:class:`shared.recording.writer.McapLog`) and plans and occupancy grids are
passed to the pure :class:`services.executor.core.ExecutorCore`.

Lock-step mode (deterministic), replanning step n = 0 .. steps-1, simulated time ``t_n = n * P``:

1. adopt the newest plan of tick <= n-1 (Fig. 4: plan n-1 is executed during step n);
2. decide once whether to hold (plan or occupancy older than ``stale_limit_s``, ages measured in
   simulated time from the message's tick: a message of tick k counts as received at ``k * P``);
3. simulate the step: ``substeps`` RobotState messages with tick n, stamps ``t_n + h .. t_n + P``
   (the last one is the configuration at which plan n will start executing);
4. publish ClockTick n (stamp ``t_n``, period P);
5. wait (at most ``lockstep_timeout_s``) for the plan of tick n.

Real-time mode: after the same wait for the ``wait_for`` services, the arm follows the newest plan
from the moment it arrives; RobotState goes out at ``state_rate_hz`` of wall time; freshness is
measured from the arrival time; no clock ticks.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from shared.config import ZenohConfig
from shared.protocol import ClockTick, DemoMarker, Keys, Message, OccupancyGrid, Plan, ProtocolError, decode
from shared.recording.foxglove import SceneBuilder
from shared.recording.writer import McapLog
from shared.scene import Scene, load_scene
from shared.transport import Presence, RejectCounter, TypedPublisher, describe, open_session

from .core import ArmLimits, ExecutorConfig, ExecutorCore, ExecutorError

__all__ = ["ExecutorResult", "ExecutorService", "load_models", "start_configuration"]

log = logging.getLogger("foresight.executor")


@dataclass
class ExecutorResult:
    """What a run did.

    Attributes:
        steps: Replanning steps completed (lock-step) or periods elapsed (real time).
        reached: Whether the goal was reached; ``reached_step`` the first step it was (-1: never).
        goal_per_step: Goal index executed during each step (-1: none yet).
        held_steps: Steps (lock-step) or state samples (real time) during which the robot held.
        plans: Plans adopted; ``plans_rejected``: plans with the wrong joints.
        rejects: Payloads that failed to decode, per key.
        mcap_path: The log, or None.
        times: ``(N,)`` stamps of the published states; ``q``: ``(N, D)`` their configurations.
    """

    steps: int = 0
    reached: bool = False
    reached_step: int = -1
    goal_per_step: list[int] = field(default_factory=list)
    held_steps: int = 0
    plans: int = 0
    plans_rejected: int = 0
    rejects: dict[str, int] = field(default_factory=dict)
    mcap_path: str | None = None
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def load_models(scene: Scene, device: str = "cpu") -> tuple[Any, Any, Any]:
    """The robot model placed in ``scene`` and the human model (``(robot, human, place_in_scene)``).

    The human model is optional for the executor (only the Foxglove view uses it): when it cannot
    be loaded, ``(robot, None, None)`` is returned with a warning.
    """
    import torch

    from shared.robot import PR2

    robot = PR2.from_scene(scene, device=device, dtype=torch.float32)
    try:
        from shared.human import HumanModel, place_in_scene

        return robot, HumanModel(), place_in_scene
    except Exception as exc:  # noqa: BLE001 - visualisation only
        log.warning("executor: human model unavailable (%s); the log will have no human body", exc)
        return robot, None, None


def start_configuration(limits: ArmLimits, config: ExecutorConfig, robot: Any = None,
                        scene: Scene | None = None) -> np.ndarray:
    """The start configuration of the arm.

    ``config.start_q`` if given, else the robot model's ``q_start``, else the scene's torso lift with
    every other joint at 0 (clamped into the limits).

    Raises:
        ExecutorError: If ``config.start_q`` has the wrong length or leaves the joint limits.
    """
    if config.start_q:
        q = np.asarray(config.start_q, dtype=np.float64)
        if q.shape != (limits.dof,):
            raise ExecutorError(f"executor.start_q: expected {limits.dof} values {list(limits.joint_names)}, "
                                f"got {len(config.start_q)}")
        bad = [n for n, v, lo, hi in zip(limits.joint_names, q, limits.lower, limits.upper, strict=True)
               if not lo - 1e-9 <= v <= hi + 1e-9]
        if bad:
            raise ExecutorError(f"executor.start_q: outside the joint limits for {bad}")
        return q
    q_start = getattr(robot, "q_start", None)
    if q_start is not None:
        arr = q_start.detach().cpu().numpy() if hasattr(q_start, "detach") else q_start
        return limits.clamp(np.asarray(arr, dtype=np.float64))
    q = np.zeros(limits.dof)
    if scene is not None and "torso_lift_joint" in limits.joint_names:
        q[limits.joint_names.index("torso_lift_joint")] = scene.robot.torso_lift
    return limits.clamp(q)


class ExecutorService:
    """The executor process: simulation master, safety hold, RobotState and clock publisher, MCAP logger.

    Args:
        config: Executor options.
        zenoh: Zenoh session options (prefix, endpoints).
        stop: Set it to end the run early (e.g. on SIGINT/SIGTERM).
        robot: Robot model (default: ``shared.robot.PR2`` placed in the scene).
        human: Human model and ``place_in_scene`` for the Foxglove view (default: shared.human).
        scene: The scene (default: ``config.scene``).
    """

    def __init__(self, config: ExecutorConfig, zenoh: ZenohConfig, stop: threading.Event | None = None,
                 robot: Any = None, human: tuple[Any, Any] | None = None, scene: Scene | None = None) -> None:
        config.validate()
        self.config = config
        self.zenoh = zenoh
        self.keys = Keys(zenoh.prefix)
        self.stop = stop or threading.Event()
        self.scene = scene or load_scene(config.scene or None)
        if robot is None:
            robot, human_model, place = load_models(self.scene, config.device)
            if human is None:
                human = (human_model, place)
        self.robot = robot
        self.human = human or (None, None)
        self.limits = ArmLimits.from_robot(robot)
        q0 = start_configuration(self.limits, config, robot, self.scene)
        self.core = ExecutorCore(self.limits, q0, config)
        self.rejects = RejectCounter("executor")
        self._expected = self.keys.data_keys()
        self.result = ExecutorResult()
        self._cond = threading.Condition()
        self._latest_plan: Plan | None = None     # newest valid plan received
        self._plan_seq = 0
        self._occ_tick = -1                        # newest occupancy tick (lock-step)
        self._occ_time: float | None = None        # arrival (monotonic) of the newest occupancy (real time)
        self._t0 = time.monotonic()
        self.mcap: McapLog | None = None
        self._times: list[float] = []
        self._qs: list[np.ndarray] = []

    # -- inputs (Zenoh threads) ------------------------------------------------------------------

    def _on_sample(self, key: str, payload: bytes) -> None:
        try:
            msg = decode(payload, self._expected.get(key))
        except ProtocolError as exc:
            self.rejects.reject(key, exc)  # counted, logged (rate-limited) with the decoder's message
            if self.mcap is not None:
                self.mcap.reject(key, payload, str(exc), quiet=True)
            return
        if self.mcap is not None:
            self.mcap.log_message(key, payload, msg)
        self._dispatch(key, msg)

    def _dispatch(self, key: str, msg: Message) -> None:
        if key == self.keys.plan and isinstance(msg, Plan):
            try:
                self.core.check_plan(msg)
            except ExecutorError as exc:
                self.result.plans_rejected += 1
                self.rejects.reject(key, exc)
                return
            with self._cond:
                self._latest_plan = msg
                self._plan_seq += 1
                self._cond.notify_all()
        elif key == self.keys.demo and isinstance(msg, DemoMarker):
            with self._cond:
                self.core.note_demonstration(msg.event)
        elif key == self.keys.occupancy and isinstance(msg, OccupancyGrid):
            with self._cond:
                self._occ_tick = max(self._occ_tick, msg.tick)
                self._occ_time = time.monotonic()
                self._cond.notify_all()

    # -- run -------------------------------------------------------------------------------------

    def run(self) -> ExecutorResult:
        """Run until ``steps`` are done, the goal is reached (``stop_on_goal``) or ``stop`` is set."""
        cfg = self.config
        now = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        path = cfg.mcap_path(now)
        with open_session(self.zenoh) as session:
            if path is not None:
                builder = SceneBuilder(self.scene, self.robot, *self.human)
                text = Path(self.scene.source).read_text() if Path(self.scene.source).is_file() else None
                if text is None:
                    from importlib import resources

                    res = resources.files("shared") / "data" / "scenes" / Path(self.scene.source).name
                    text = res.read_text() if res.is_file() else None
                meta = {f.name: str(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
                meta.update(prefix=self.zenoh.prefix, joint_names=",".join(self.limits.joint_names))
                self.mcap = McapLog(path, self.keys, builder, viz_period_s=1.0 / cfg.viz_rate_hz,
                                    scene_text=text, run_metadata=meta)
                self.result.mcap_path = str(path)
            sub = session.declare_subscriber(f"{self.zenoh.prefix}/**",
                                             lambda s: self._on_sample(str(s.key_expr), s.payload.to_bytes()))
            # block (never drop) under congestion: lock-step consumers count on every state and tick
            state_pub: TypedPublisher[Any] = TypedPublisher(session, self.keys.robot_state, block=True)
            clock_pub: TypedPublisher[Any] = TypedPublisher(session, self.keys.clock, block=True)
            presence = Presence(session, self.keys, "executor")
            log.info("executor: %s mode, %d steps of %.3f s, log %s, session %s", cfg.mode, cfg.steps,
                     cfg.step_period_s, path, describe(session)["zid"])
            try:
                if cfg.mode == "lockstep":
                    self._run_lockstep(state_pub, clock_pub, presence)
                else:
                    self._run_realtime(state_pub, presence)
                time.sleep(0.3)  # let the last messages of the run reach the logger
            finally:
                presence.close()
                sub.undeclare()
                if self.mcap is not None:
                    self.mcap.close()
        r = self.result
        r.rejects = dict(self.rejects.counts)
        r.plans = self.core.plans_adopted
        r.times = np.asarray(self._times)
        r.q = np.asarray(self._qs).reshape(len(self._qs), self.limits.dof)
        log.info("executor: done after %d steps, goal %s, reached=%s (step %d), %d plans, %d held, %d rejected",
                 r.steps, r.goal_per_step[-1] if r.goal_per_step else -1, r.reached, r.reached_step, r.plans,
                 r.held_steps, sum(r.rejects.values()))
        return r

    def _publish_state(self, pub: TypedPublisher[Any], tick: int, stamp: float) -> None:
        pub.put(self.core.state(tick, stamp))
        if self.mcap is not None:
            self.mcap.flush_if_due()
        self._times.append(stamp)
        self._qs.append(self.core.q.copy())

    def _wait_for_peers(self, presence: Presence) -> None:
        cfg = self.config
        deadline = time.monotonic() + cfg.startup_timeout_s
        missing = [s for s in ("replayer", "predictor", "planner") if s in cfg.wait_for]
        while missing and not self.stop.is_set() and time.monotonic() < deadline:
            missing = [s for s in missing if not presence.is_alive(s)]
            if missing:
                time.sleep(0.05)
        if missing:
            log.warning("executor: starting without %s (not seen within %.0f s)", missing, cfg.startup_timeout_s)
        elif cfg.wait_for:
            log.info("executor: %s present, starting the run", ", ".join(cfg.wait_for))

    def _run_lockstep(self, state_pub: TypedPublisher[Any], clock_pub: TypedPublisher[Any],
                      presence: Presence) -> None:
        cfg, core = self.config, self.core
        period, sub = cfg.step_period_s, cfg.substeps
        h = period / sub
        self._wait_for_peers(presence)
        self._publish_state(state_pub, -1, 0.0)
        adopted_seq = 0
        n = 0
        while (cfg.steps == 0 or n < cfg.steps) and not self.stop.is_set():
            t_n = n * period
            with self._cond:
                plan, seq, occ_tick = self._latest_plan, self._plan_seq, self._occ_tick
            if plan is not None and seq != adopted_seq and plan.tick <= n - 1:
                core.adopt(plan, stamp=plan.tick * period)
                adopted_seq = seq
            if occ_tick >= 0:
                core.note_occupancy(occ_tick * period)
            reason = core.stale_reason(t_n)
            if reason:
                self.result.held_steps += 1
                if reason != "waiting for the first plan" or n > 0:
                    log.info("executor: holding during step %d: %s", n, reason)
            for i in range(sub):
                core.step(h, hold_reason=reason)
                core.t = t_n + (i + 1) * h  # no drift from summing h
                self._publish_state(state_pub, n, core.t)
            self.result.goal_per_step.append(core.goal)
            self.result.steps = n + 1
            if core.reached and self.result.reached_step < 0:
                self.result.reached, self.result.reached_step = True, n
                log.info("executor: goal %d reached during step %d", core.goal, n)
            clock_pub.put(ClockTick(stamp=t_n, tick=n, period=period))
            if cfg.stop_on_goal and core.reached:
                break
            if not self._wait_plan(n):
                log.warning("executor: no plan for tick %d within %.1f s; going on", n, cfg.lockstep_timeout_s)
            n += 1

    def _wait_plan(self, tick: int) -> bool:
        deadline = time.monotonic() + self.config.lockstep_timeout_s
        with self._cond:
            while not self.stop.is_set():
                if self._latest_plan is not None and self._latest_plan.tick >= tick:
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.1))
                if self.mcap is not None:
                    self.mcap.flush_if_due()
        return False

    def _run_realtime(self, state_pub: TypedPublisher[Any], presence: Presence) -> None:
        cfg, core = self.config, self.core
        self._wait_for_peers(presence)  # the run's clock starts once the planner (and the rest) are there
        period = cfg.step_period_s
        h_nom = 1.0 / cfg.state_rate_hz
        end = cfg.steps * period if cfg.steps else float("inf")
        self._t0 = t0 = time.monotonic()
        adopted_seq = 0
        next_wake = t0
        last_reason = None
        while not self.stop.is_set() and core.t < end:
            next_wake += h_nom
            delay = next_wake - time.monotonic()
            if delay > 0:
                self.stop.wait(delay)
            elapsed = time.monotonic() - t0
            with self._cond:
                plan, seq, occ_time = self._latest_plan, self._plan_seq, self._occ_time
            if plan is not None and seq != adopted_seq:
                core.adopt(plan)  # starts now; counts as received now
                adopted_seq = seq
            if occ_time is not None:
                core.note_occupancy(occ_time - t0)
            h = max(elapsed - core.t, 1e-6)
            core.step(h)
            if core.holding:
                self.result.held_steps += 1
            if core.reason != last_reason:
                if core.reason:
                    log.info("executor: holding at t=%.2f s: %s", core.t, core.reason)
                elif last_reason is not None:
                    log.info("executor: resuming at t=%.2f s", core.t)
                last_reason = core.reason
            self._publish_state(state_pub, -1, time.time())
            step = int(core.t // period)
            while len(self.result.goal_per_step) < step:
                self.result.goal_per_step.append(core.goal)
            self.result.steps = step
            if core.reached and self.result.reached_step < 0:
                self.result.reached, self.result.reached_step = True, step
                log.info("executor: goal %d reached at t=%.2f s", core.goal, core.t)
                if cfg.stop_on_goal:
                    break
