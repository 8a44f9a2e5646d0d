"""The executor service: the simulation master of a run and its MCAP logger.

One Zenoh subscriber on ``<prefix>/**`` receives every message of the run (its own included): each
payload is checked (:class:`shared.protocol.Receipt`: decoded, its values against this robot, scene
grid and clock, its ticks and sequence numbers per sender); a payload that passes is logged
(:class:`shared.recording.writer.McapLog`) and plans and occupancy grids are passed to the pure
:class:`services.executor.core.ExecutorCore`; one that fails is counted per key and reason and goes
to the log's rejects channel only.

Lock-step mode (deterministic), replanning step n = 0 .. steps-1: the rules (plan adoption, the hold
decided once per step, the substeps and the tick) are :class:`shared.lockstep.LockstepMaster`'s; this
loop publishes the step's ``substeps`` RobotState messages and ClockTick n, then waits (at most
``lockstep_timeout_s``) for the plan of tick n in its :class:`shared.lockstep.PlanInbox`.

Real-time mode (:mod:`services.executor.realtime`): after the same wait for the ``wait_for`` services, the arm
follows the newest plan from the moment it arrives; RobotState goes out at ``state_rate_hz`` of wall time;
freshness is measured from the arrival time; no clock ticks.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from contextlib import ExitStack
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from shared.config import ZenohConfig
from shared.foxglove.scene import SceneBuilder
from shared.lockstep import FIRST_PLAN, LockstepMaster, PlanInbox, StepClock
from shared.protocol import (
    DemoMarker,
    Expectations,
    GridSpec,
    HumanPose,
    Keys,
    Message,
    OccupancyGrid,
    Plan,
    ProtocolError,
    Receipt,
    RobotSpec,
    RobotState,
)
from shared.recording.writer import McapLog
from shared.scene import Scene, load_scene
from shared.security.guard import denied
from shared.transport import Presence, RejectCounter, TypedPublisher, describe, open_session, sender_of

from .core import ArmLimits, ExecutorConfig, ExecutorCore, ExecutorError, reason_kind
from .models import HumanBody, PlaceInScene, RobotModel, load_models, start_configuration
from .peers import PeerWatch
from .realtime import run_realtime
from .result import ExecutorResult
from .separation import separation_guard

if TYPE_CHECKING:
    from shared.foxglove.live import LiveServer

__all__ = ["ExecutorResult", "ExecutorService", "load_models", "start_configuration"]  # all but one: .result, .models

log = logging.getLogger("foresight.executor")

LINGER_S = 0.3
"""Seconds the session stays open after the run so that its last messages reach the log (none without one)."""
POSES_KEPT = 4096
"""Arrival times of the newest poses kept to date the occupancy grids made from them (real time)."""


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
                 robot: RobotModel | None = None, human: tuple[HumanBody | None, PlaceInScene | None] | None = None,
                 scene: Scene | None = None) -> None:
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
        self.human: tuple[HumanBody | None, PlaceInScene | None] = human or (None, None)
        self.limits = ArmLimits.from_robot(robot)
        q0 = start_configuration(self.limits, config, robot, self.scene)
        self.guard = separation_guard(config, robot, self.scene)  # real time, else None
        self.core = ExecutorCore(self.limits, q0, config, guard=self.guard)
        self.rejects = RejectCounter("executor", known_keys=self.keys.data_keys())
        lim = self.limits
        lockstep = config.mode == "lockstep"
        self.receipt = Receipt(Expectations(
            clock=config.mode, period_s=config.step_period_s if lockstep else None,
            # no tick beyond the one in progress (the steps after the last one, finish_path, count too)
            max_tick=(lambda: self.result.steps + self.result.finish_steps) if lockstep else None,
            robot=RobotSpec(tuple(lim.joint_names), lim.lower, lim.upper, lim.velocity),
            grid=GridSpec.from_grid(self.scene.grid)))
        self._expected = self.keys.data_keys()
        k = self.keys
        self._dispatched = frozenset((k.plan, k.demo, k.pose, k.occupancy))  # the keys _dispatch acts on
        self.result = ExecutorResult()
        self.inbox = PlanInbox()
        self._pose_arrival: OrderedDict[tuple[int, int], float] = OrderedDict()  # (demo_id, index) -> arrival
        self.peers = PeerWatch(config)
        self.mcap: McapLog | None = None
        self.live: LiveServer | None = None  # the live server (live_port), fed by the log
        self._times: list[float] = []
        self._qs: list[np.ndarray] = []

    # -- inputs (Zenoh threads) ------------------------------------------------------------------

    def _on_zenoh(self, sample: Any) -> None:
        """Zenoh's callback for ``<prefix>/**``: every key goes to the log; with no log, only what the executor uses.

        Without a log, its own states and ticks, the posteriors and the keypoints (most of a lock-step run's
        messages: 25 states a step) are neither checked nor decoded here: no one in this process reads them.
        Their consumers check them (the planner its states, the harness everything it records).
        """
        key = str(sample.key_expr)
        if self.mcap is None and key not in self._dispatched:
            return
        self._on_sample(key, sample.payload.to_bytes(), sender_of(sample))

    def _on_sample(self, key: str, payload: bytes, sender: str = "") -> None:
        try:
            msg = self.receipt.accept(key, payload, self._expected.get(key), sender)
        except Exception as exc:  # ProtocolError; anything else is a decoder bug, refused all the same
            if isinstance(exc, ProtocolError):
                self.rejects.reject(key, exc)  # counted per reason, logged (rate-limited)
            else:
                self.rejects.unexpected(key, exc, "checking a message")  # its traceback once per key
            if self.mcap is not None:  # never on the key's data channel: the rejects channel only
                mcap, why, reason = self.mcap, str(exc), getattr(exc, "reason", "malformed")
                self._write(lambda: mcap.reject(key, payload, why, quiet=True, reason=reason))
            return
        if self.mcap is not None:
            mcap = self.mcap
            self._write(lambda: mcap.log_message(key, payload, msg))
        try:
            self._dispatch(key, msg)  # the robot gets its input whether or not the log could take it
        except Exception as exc:  # a bug handling a valid message: counted and said, never raised into Zenoh's thread
            self.rejects.unexpected(key, exc, f"handling a {msg.TYPE}")

    def _write(self, write: Callable[[], None]) -> None:
        """Write to the log; a failure (a full disk) is logged, the first and every 100th, and counted."""
        try:
            write()
        except Exception as exc:
            self.result.log_write_failures += 1
            n = self.result.log_write_failures
            if n == 1 or n % 100 == 0:
                log.error("executor: writing the MCAP log failed (%d so far): %s: %s", n, type(exc).__name__, exc)

    def _close_log(self) -> None:
        """Close the log; one a full disk left incomplete goes in the result (its line, the messages lost)."""
        mcap = self.mcap
        if mcap is None:
            return
        try:
            mcap.close()  # retries what the disk refused for a few seconds first (CLOSE_RETRY_S)
        except Exception as exc:  # said by the log in one line (INCOMPLETE: N of M messages written)
            self.result.log_write_failures += 1
            self.result.log_incomplete = str(exc.strerror if isinstance(exc, OSError) and exc.strerror else exc)
        self.result.log_lost = mcap.ledger.lost

    def _dispatch(self, key: str, msg: Message) -> None:
        if key == self.keys.plan and isinstance(msg, Plan):
            try:
                self.core.check_plan(msg)
            except ExecutorError as exc:
                self.result.plans_rejected += 1
                self.rejects.reject(key, exc, reason="mismatch")
                return
            self.inbox.put_plan(msg)
        elif key == self.keys.demo and isinstance(msg, DemoMarker):
            self.core.note_demonstration(msg.event, msg.demo_id, msg.n_samples)
            self.inbox.put_marker(msg.event, msg.tick)
        elif key == self.keys.pose and isinstance(msg, HumanPose):
            self._pose_arrival[(msg.demo_id, msg.index)] = time.monotonic()
            if self.guard is not None:
                self.guard.note_pose(msg.demo_id, msg.index, msg.features, msg.stamp)
            if len(self._pose_arrival) > POSES_KEPT:
                self._pose_arrival.popitem(last=False)
        elif key == self.keys.occupancy and isinstance(msg, OccupancyGrid):
            self.core.note_occupancy_of(msg.demo_id, msg.index)
            # a prediction is as old as the pose it was made from: a predictor draining a backlog (or
            # after the human's stream died) publishes grids that arrive now but describe the past
            now = time.monotonic()
            self.inbox.put_occupancy(msg.tick, min(now, self._pose_arrival.get((msg.demo_id, msg.index), now)))

    def _on_peer(self, service: str, alive: bool) -> None:
        self.peers.note(service, alive, self.core)

    # -- run -------------------------------------------------------------------------------------

    def run(self) -> ExecutorResult:
        """Run until ``steps`` are done, the goal is reached (``stop_on_goal``) or ``stop`` is set."""
        cfg = self.config
        now = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        path: Path | None = None
        # the log and the live server close on every way out, the log first (it drains into the server)
        with open_session(self.zenoh, self.stop, "executor") as session, ExitStack() as closing:
            if cfg.mcap.lower() != "none":
                builder = SceneBuilder(self.scene, self.robot, *self.human)
                text = self.scene.text()
                meta = {f.name: str(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
                meta.update(prefix=self.zenoh.prefix, joint_names=",".join(self.limits.joint_names))
                # real time: Foxglove updates on a background thread (never ahead of a plan's receipt); lock-step:
                # in the callback, so that a run's log never depends on thread timing (no update ever dropped)
                live = self._live_server(builder)
                if live is not None:
                    closing.callback(live.close)
                path = cfg.mcap_path(now)  # the default name claimed (an empty file) once nothing else can fail first
                self.mcap = McapLog(path, self.keys, builder, viz_period_s=1.0 / cfg.viz_rate_hz,
                                    viz_thread=cfg.mode != "lockstep", compression=cfg.mcap_compression,
                                    scene_text=text, run_metadata=meta, on_viz=live.log if live else None)
                closing.callback(self._close_log)  # a full disk's failure: counted, said
                self.result.mcap_path = str(path)
            link = self._connect_robot(session) if cfg.robot == "ros2" else None
            if refused := denied(session, f"{self.zenoh.prefix}/**", "subscribe"):  # the log would stay empty
                log.warning("access control: %s", refused)
            sub = session.declare_subscriber(f"{self.zenoh.prefix}/**", self._on_zenoh)
            # block (never drop) under congestion: lock-step consumers count on every state and tick
            state_pub: TypedPublisher[Any] = TypedPublisher(session, self.keys.robot_state, block=True)
            clock_pub: TypedPublisher[Any] = TypedPublisher(session, self.keys.clock, block=True)
            presence = Presence(session, self.keys, "executor", on_change=self._on_peer)
            log.info("executor: %s mode, %d steps of %.3f s, log %s, session %s", cfg.mode, cfg.steps,
                     cfg.step_period_s, path, describe(session)["zid"])
            if note := cfg.state_rate_note():
                log.info(note)
            try:
                if cfg.mode == "lockstep":
                    self._run_lockstep(state_pub, clock_pub, presence)
                else:
                    run_realtime(self, state_pub, presence)
                if self.mcap is not None:
                    time.sleep(LINGER_S)  # let the last messages of the run reach the logger
            finally:
                presence.close()
                sub.undeclare()
                if link is not None:
                    link.close()
        r = self.result
        r.rejects = dict(self.rejects.counts)
        r.reject_reasons = {f"{k} {why}": n for (k, why), n in sorted(self.rejects.by_reason.items())}
        r.plans = self.core.plans_adopted
        r.separation_holds = self.guard.holds_ if self.guard is not None else 0
        if self.mcap is not None and (late := self.mcap.dropped_after_close):  # said once by the log as it came
            r.log_dropped_after_close = late
            log.warning("executor: %d message(s) came after the MCAP log was closed: not in it", late)
        r.times = np.asarray(self._times)
        r.q = np.asarray(self._qs).reshape(len(self._qs), self.limits.dof)
        if r.lockstep_timeouts:
            log.warning("executor: %d tick(s) went on without their plan or prediction (waited %.0f s each): not the "
                        "run its seed makes (the experiments refuse such a run)", r.lockstep_timeouts,
                        self.config.lockstep_timeout_s)
        held = "steps" if self.config.mode == "lockstep" else "state samples"  # what ExecutorResult.held_steps counts
        held += f" ({r.separation_holds} by the separation guard)" * bool(r.separation_holds)
        log.info("executor: done after %d steps, %s, %d plans adopted, held during %d %s, %d rejected: %s", r.steps,
                 r.final_goal(), r.plans, r.held_steps, held, sum(r.rejects.values()), self.rejects.summary())
        return r

    def _live_server(self, builder: SceneBuilder) -> LiveServer | None:
        """``live_port``: Foxglove's WebSocket server, fed every scene message the log writes (None: off)."""
        if not self.config.live_port:
            return None
        from shared.foxglove.live import LiveServer
        from shared.foxglove.stream import SceneStream

        self.live = LiveServer(self.config.live_port, self.config.live_host, static=SceneStream(builder).static)
        log.info("executor: serving the scene live at %s (Foxglove: Open connection -> Foxglove WebSocket)",
                 self.live.url)
        return self.live

    def _connect_robot(self, session: Any) -> Any:
        """``robot = "ros2"``: find the ROS 2 robot and drive it (:class:`services.ros2.arm.Ros2Arm`) from here on."""
        from services.ros2.arm import Ros2Arm
        from services.ros2.link import Ros2RobotLink

        record = self._record_ros2 if self.mcap is not None else None
        link = Ros2RobotLink(session, self.config, list(self.limits.joint_names), self.stop, self.rejects, record)
        try:
            q0 = link.initial(self.config.startup_timeout_s)
        except BaseException:
            link.close()
            if self.mcap is not None:
                self._close_log()  # complete, with what it has: the run never started
            raise
        self.core = Ros2Arm(self.limits, q0, self.config, link, guard=self.guard)
        return link

    def _record_ros2(self, topic: str, msgtype: str, data: bytes) -> None:
        """Log a ROS 2 message the link sent or received, guarded as every write is (:meth:`_write`).

        Passed to the link bare, a log the disk had ended raised from ``send`` after the command had gone out (the run
        ended without a hold) and from the joint-state callback before the state was taken (it was dropped).
        """
        mcap = self.mcap
        if mcap is not None:
            self._write(lambda: mcap.write_ros2(topic, msgtype, data))

    def publish_state(self, pub: TypedPublisher[Any], state: RobotState) -> None:
        """Publish ``state``, flush the log when due, and keep it for the result's ``times`` and ``q``."""
        pub.put(state)
        if self.mcap is not None:
            self._write(self.mcap.flush_if_due)  # a full disk costs the robot nothing
        self._times.append(state.stamp)
        self._qs.append(state.q)

    def wait_for_peers(self, presence: Presence) -> None:
        """Wait (at most ``startup_timeout_s``) for the ``wait_for`` services' liveliness tokens."""
        cfg = self.config
        presence.wait_for(cfg.wait_for, cfg.startup_timeout_s, self.stop)

    def _run_lockstep(self, state_pub: TypedPublisher[Any], clock_pub: TypedPublisher[Any],
                      presence: Presence) -> None:
        cfg, r = self.config, self.result
        master = LockstepMaster(self.core, StepClock(cfg.step_period_s, cfg.substeps))
        self.wait_for_peers(presence)
        self.publish_state(state_pub, master.initial_state())
        n, last_kind = 0, None
        while (cfg.steps == 0 or n < cfg.steps) and not self.stop.is_set():
            step = master.step(n, self.inbox.latest())
            r.held_steps += int(step.held)
            if reason_kind(step.reason) != last_kind:  # each change once, not every step
                if step.hold_news:
                    log.info("executor: holding from step %d: %s", n, step.reason)
                elif not step.held and last_kind not in (None, FIRST_PLAN):
                    log.info("executor: resuming at step %d", n)
                last_kind = reason_kind(step.reason)
            for state in step.states:
                self.publish_state(state_pub, state)
            r.goal_per_step.append(step.goal)
            r.steps = n + 1
            if step.reached and r.note_reached(step.goal, n):
                log.info("executor: goal %d reached during step %d", step.goal, n)
            clock_pub.put(step.clock)
            if cfg.stop_on_goal and step.reached:
                return  # at the goal: nothing left to finish
            flush = partial(self._write, self.mcap.flush_if_due) if self.mcap is not None else None
            wait, stop = cfg.lockstep_timeout_s, self.stop
            missing = ("plan" if not self.inbox.wait_plan(n, wait, stop, idle=flush) else "prediction"
                       if cfg.require_occupancy and not self.inbox.wait_occupancy(n, wait, stop, idle=flush) else "")
            if missing and not stop.is_set():  # counted: the experiments refuse such a run (harness.LateInputs)
                r.lockstep_timeouts += 1
                log.warning("executor: no %s for tick %d within %.1f s; going on", missing, n, wait)
            n += 1
        if cfg.finish_path and not self.stop.is_set():
            self._finish_path(master, state_pub, n)

    def _finish_path(self, master: LockstepMaster, state_pub: TypedPublisher[Any], n: int) -> None:
        """After the last step: the rest of the last plan at the same pace, without replanning (paper protocol).

        The first of these steps adopts the plan of the last replanning step (as any step adopts the plan of the one
        before); a bounded number of steps follows (its length at the pace, and 20 more for a lagging joint).
        """
        cfg, r, core = self.config, self.result, self.core
        per_step = cfg.path_per_step if cfg.path_per_step > 0 else cfg.step_period_s
        start, bound = n, n + 1
        received = self.inbox.latest()  # the last step's plan: the rest of the best path is the newest plan's
        while (n == start or (core.remaining > 0.0 and n < bound)) and not self.stop.is_set():
            r.finish_steps += 1  # before its states go out: they carry tick n
            step = master.finish(n, received if n == start else None)
            if n == start:  # a bounded tail: the plan's length at the pace, 20 steps more for a lagging joint
                bound = n + 1 + math.ceil(core.remaining / per_step) + 20
            for state in step.states:
                self.publish_state(state_pub, state)
            if step.reached and r.note_reached(step.goal, n):
                log.info("executor: goal %d reached during step %d (the rest of the path)", step.goal, n)
            n += 1

