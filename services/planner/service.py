"""The planner's Zenoh loop: occupancy + robot state in, one Plan per replanning step out.

Lock-step mode (deterministic; see docs/protocol.md): on ClockTick n the planner takes what its
:class:`shared.lockstep_followers.TickInbox` pairs with the tick,

* the robot configuration at the end of step n, i.e. the last RobotState of tick n (stamp
  ``tick.stamp + tick.period``), which is where plan n starts executing, and
* the prediction made during step n-1 (Fig. 4 of the paper): the OccupancyGrid of tick n-1 with
  ``tick_last`` (none at tick 0: an empty grid),

waiting for each at most ``input_timeout_s``, runs :meth:`Planner.step` and publishes Plan(tick=n).

Real-time mode: the planner plans from the newest robot state with the newest occupancy (latest-only
subscriptions, so a slow planner never works through stale grids). With ``trigger = "event"`` (default)
a step starts as soon as the planner is idle and a new prediction has arrived or the robot has left its
plan, ``period_s`` being the longest gap (:mod:`services.planner.replan`); the plan starts one recent
planning time (at most ``lookahead_s``) ahead along the previous tau_best, where the robot will be when
it arrives. With ``trigger = "period"`` it plans every ``period_s``, as far ahead (the executor adopts a plan as it
arrives in either mode). A robot off its plan is planned for from where its velocity takes it over that time. Each Plan
carries the inputs it used: ``stamp`` is the RobotState's stamp, ``occupancy_tick``/``occupancy_index``
the prediction's. With ``cost.body_clearance`` > 0 it also follows the person's poses: each step keeps clear of the
body of the newest (:mod:`services.planner.body`), which the executor's separation guard measures too (the guard
takes the nearest body of the last ``window_s``; the planner the newest alone, by design: see there).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from shared.config import ZenohConfig
from shared.lockstep_followers import TickInbox
from shared.log_summary import PeriodicSummary
from shared.protocol import (
    ClockTick,
    DemoMarker,
    Expectations,
    GridSpec,
    HumanPose,
    Keys,
    OccupancyGrid,
    Plan,
    Receipt,
    RobotSpec,
    RobotState,
)
from shared.scene import Scene, load_scene
from shared.transport import (
    LatestSubscriber,
    Presence,
    RejectCounter,
    TypedPublisher,
    describe,
    open_session,
    subscribe,
)

from .body import PersonBody
from .config import PlannerServiceConfig
from .core import Planner, PlannerError, PlanResult
from .replan import ReplanTrigger

__all__ = ["PlannerServiceConfig", "PlannerService", "PlannerStats", "plan_message", "occupancy_identity"]

log = logging.getLogger("foresight.planner")


@dataclass
class PlannerStats:
    """What the service did."""

    plans: int = 0
    failures: int = 0
    last_error: str = ""
    late_inputs: int = 0  # lock-step: ticks planned from an older state or prediction after the wait ran out
    last_late: str = ""


def plan_message(result: PlanResult, tick: int, stamp: float, occupancy: OccupancyGrid | None) -> Plan:
    """The Plan message of a planning result.

    Args:
        result: Output of :meth:`Planner.step`.
        tick: Clock tick (-1 in real-time mode).
        stamp: Message time (simulated in lock-step, wall clock in real time).
        occupancy: The prediction planned against (None: the empty grid).
    """
    return Plan(stamp=float(stamp), tick=tick, step=result.step, goal_names=list(result.goal_names),
                joint_names=list(result.joint_names), dt=float(result.dt), chosen=int(result.chosen),
                planning_ms=float(result.planning_ms),
                occupancy_tick=occupancy.tick if occupancy is not None else -1,
                occupancy_index=occupancy.index if occupancy is not None else -1,
                trajectories=result.trajectories.astype(np.float32), cost_smoothness=result.cost_smoothness,
                cost_obstacle=result.cost_obstacle, cost_human=result.cost_human, cost_total=result.cost_total,
                valid=result.valid.astype(bool))


class PlannerService:
    """Wraps a :class:`Planner` in a Zenoh session.

    Args:
        config: Service + planner options.
        zenoh: Session options.
        planner: A ready planner (default: built from ``config`` and the scene).
        scene: The scene (default: ``config.scene``).
    """

    def __init__(self, config: PlannerServiceConfig, zenoh: ZenohConfig, planner: Planner | None = None,
                 scene: Scene | None = None) -> None:
        config.validate()
        self.config = config
        self.zenoh = zenoh
        self.scene = scene or load_scene(config.scene or None)
        self.planner = planner or Planner(self.scene, config.planner_config())
        self.keys = Keys(zenoh.prefix)
        self.rejects = RejectCounter("planner", known_keys=self.keys.data_keys())
        # what arrives is checked against this planner's robot and scene grid (shared.protocol.receipt); a grid
        # finer than half the scene grid's resolution (8x its voxels) is refused: its lookup tables are the cost
        self.receipt = Receipt(Expectations(clock=config.mode, robot=RobotSpec.from_robot(self.planner.robot),
                                            grid=GridSpec.planning(self.scene.grid)))
        self.stats = PlannerStats()
        self._empty = np.zeros(self.scene.grid.dims, dtype=np.float32)
        self.trigger: ReplanTrigger | None = None  # real-time mode: when steps start (and why, counted)
        self.summary = PeriodicSummary(log, "planner: plans")  # each plan at DEBUG, a summary at INFO
        self._body_poses = 0  # real time: the person's poses seen when the cost's body was last set
        self._failure_said, self._failures_said = -math.inf, 0  # when a failed step was last logged, and the count
        # the joint limits an off-path start is clipped into (_start_of), as numpy once: they are the planner's, fixed
        self._limits = tuple(np.asarray(b.cpu(), dtype=np.float64) for b in (self.planner.lower, self.planner.upper))

    def _start_of(self, robot: RobotState, lookahead: float | None) -> tuple[np.ndarray, float | None]:
        """Real time: the configuration a step plans from, and the lookahead the planner then applies.

        On its plan, the robot is where the planner looks ``lookahead`` ahead along it. Off it (a lagging arm, a plan
        it could not follow), the step planned from where the robot was at its state's stamp: the plan landed one
        planning time later behind the robot, which was driven back to it, and the next step was off that plan
        again (32 of 66 plans from off the path, alternating; a review). Off the path, the start is where the robot
        will be: its state moved on by its velocity over the lookahead, within the joint limits.
        """
        ahead = self.planner.config.lookahead_s if lookahead is None else lookahead
        dist = self.planner.departure(robot.q)
        if robot.holding or ahead <= 0 or dist is None or dist <= self.planner.config.off_path_tol:
            return robot.q, lookahead
        return np.clip(robot.q + robot.qd * ahead, *self._limits), 0.0

    def _plan(self, q: np.ndarray, occupancy: OccupancyGrid | None, tick: int, stamp: float,
              pub: TypedPublisher[Plan], interrupt: Callable[[], bool] | None = None,
              lookahead_s: float | None = None) -> PlanResult | None:
        try:
            result = self.planner.step(q, occupancy if occupancy is not None else self._empty, interrupt=interrupt,
                                       lookahead_s=lookahead_s)
            pub.put(plan_message(result, tick, stamp, occupancy))
        except (PlannerError, ValueError) as exc:  # bad input or no plan: log, keep serving
            self.stats.failures += 1
            self.stats.last_error = str(exc)
            now = time.monotonic()  # a failure that persists repeats at the state rate in real time: a line a second
            if now - self._failure_said >= 1.0:
                more = self.stats.failures - self._failures_said - 1
                log.error("planner: step at tick %d failed: %s%s", tick, exc,
                          f" ({more} more failed steps since the last such line)" if more else "")
                self._failure_said, self._failures_said = now, self.stats.failures
            return None
        self.stats.plans += 1
        costs = ", ".join(f"{n}={c:.3g}" for n, c in zip(result.goal_names, result.cost_total, strict=True))
        log.debug("planner: tick %d step %d chose %s (%s) in %.0f ms, %d STOMP iterations", tick, result.step,
                  result.goal_names[result.chosen], costs, result.planning_ms, result.iterations)
        self.summary.add(result.planning_ms, f"chose {result.goal_names[result.chosen]}"
                         + (" from off the path" if result.off_path else ""))  # each one logged at DEBUG by the core
        return result

    def run(self, stop: threading.Event | None = None) -> PlannerStats:
        """Serve until ``stop`` is set."""
        stop = stop or threading.Event()
        with open_session(self.zenoh, stop, "planner") as session:
            pub: TypedPublisher[Plan] = TypedPublisher(session, self.keys.plan, block=True)
            log.info("planner: %s mode, %d goals %s, session %s", self.config.mode, len(self.planner.goals.names),
                     self.planner.goals.names, describe(session)["zid"])
            if self.config.mode == "lockstep":
                self._run_lockstep(session, pub, stop)
            else:
                self._run_realtime(session, pub, stop)
        self.summary.flush()
        log.info("planner: stopped after making %d plans (%d failed), rejected: %s", self.stats.plans,
                 self.stats.failures, self.rejects.summary())
        return self.stats

    def _run_lockstep(self, session: object, pub: TypedPublisher[Plan], stop: threading.Event) -> None:
        inbox = TickInbox()
        r, rc = self.rejects, self.receipt
        subs = [subscribe(session, self.keys.robot_state, RobotState, inbox.add_state, r, rc),
                subscribe(session, self.keys.occupancy, OccupancyGrid, inbox.add_occupancy, r, rc),
                subscribe(session, self.keys.clock, ClockTick, inbox.add_tick, r, rc),
                subscribe(session, self.keys.demo, DemoMarker, inbox.add_marker, r, rc)]
        presence = Presence(session, self.keys, "planner",  # announce only once subscribed
                            stop_with=self.config.stop_with, stop=stop)
        try:
            while not stop.is_set():
                tick = inbox.ticks.get(timeout=0.05)  # the stop event's latency
                if tick is None:
                    continue
                if tick.tick == 0:
                    self.planner.reset()
                wait = self.config.input_timeout_s
                got = inbox.inputs(tick, wait, stop)
                if stop.is_set():  # stopped while waiting: plan nothing more (the planner may serve the next run)
                    break
                if got.state is None:
                    log.error("planner: no robot state for tick %d within %.1f s; skipping it", tick.tick, wait)
                    self.stats.failures += 1
                    continue
                occ = got.occupancy
                late = []
                if got.state_late:
                    late.append(f"the robot state of tick {tick.tick} stamped {got.state.stamp:.3f} s, before the "
                                f"tick's end")
                if got.prediction_missing:
                    late.append(f"the prediction of tick {tick.tick - 1} (planned with "
                                f"{'an empty grid' if occ is None else f'the one of tick {occ.tick}'})")
                if late:
                    self.stats.late_inputs += 1
                    self.stats.last_late = f"tick {tick.tick}: {'; '.join(late)} after {wait:.1f} s"
                    log.warning("planner: planning tick %d without %s", tick.tick, " or ".join(late))
                self._plan(got.state.q, occ, tick.tick, tick.stamp, pub)
        finally:
            presence.close()
            for s in subs:
                s.undeclare()

    def _run_realtime(self, session: object, pub: TypedPublisher[Plan], stop: threading.Event) -> None:
        wake = threading.Event()  # set by every new input: the loop re-checks its trigger at once

        def on_input(_msg: object) -> None:
            wake.set()

        occupancy = LatestSubscriber(session, self.keys.occupancy, OccupancyGrid, self.rejects, on_message=on_input,
                                     receipt=self.receipt)
        state = LatestSubscriber(session, self.keys.robot_state, RobotState, self.rejects, on_message=on_input,
                                 receipt=self.receipt)

        def on_demo(msg: DemoMarker) -> None:
            if msg.event == "start":
                log.info("planner: demonstration %d starts", msg.demo_id)

        demo_sub = subscribe(session, self.keys.demo, DemoMarker, on_demo, self.rejects, self.receipt)
        person = self._follow_person(session)
        presence = Presence(session, self.keys, "planner", stop_with=self.config.stop_with, stop=stop)
        trigger = self.trigger = ReplanTrigger(self.config.period_s, self.config.trigger)
        tol = self.planner.config.off_path_tol
        recent: deque[float] = deque(maxlen=5)  # the last steps' planning times (s): the event mode's lookahead and
        # the period's lead

        def newer_waiting() -> bool:  # anytime: a prediction newer than the one being planned against
            return trigger.newer_than_planned(occupancy_identity(occupancy.latest))

        failed_from: RobotState | None = None  # the state a step failed from: no departure step again from it

        try:
            while not stop.is_set():
                wake.clear()
                robot = state.latest
                if robot is None:
                    wake.wait(0.05)
                    continue
                occ = occupancy.latest
                ident = occupancy_identity(occ)
                departed = False
                if trigger.mode == "event" and robot is not failed_from:  # else a failing step would restart at
                    dist = self.planner.departure(robot.q)  # once, as fast as it fails, until the next state
                    departed = dist is not None and dist > tol
                now = time.monotonic()
                lead = max(recent, default=0.0)  # the period's step starts early by this: its plan lands in time
                reason = trigger.reason(now, ident, departed, lead)
                if reason is None:
                    wake.wait(trigger.wait_s(now, lead))
                    continue
                trigger.start(now, ident, reason)
                lookahead = None  # before any plan: the configured lookahead
                if robot.holding:  # held, it stays where it is: a plan starting ahead of it was left at once
                    lookahead = 0.0  # ('departure'), every other step
                elif recent:  # the executor adopts a plan as it arrives, in either trigger mode: about one planning
                    lookahead = min(self.planner.config.lookahead_s, float(np.median(recent)))  # time from now
                q_start, lookahead = self._start_of(robot, lookahead)
                if person is not None:
                    self._note_body(person[0])
                result = self._plan(q_start, occ, -1, robot.stamp, pub, interrupt=newer_waiting,
                                    lookahead_s=lookahead)
                if result is not None:
                    recent.append(result.planning_ms / 1e3)
                failed_from = robot if result is None else None
        finally:
            log.info("planner: real-time steps by trigger: %s", ", ".join(f"{k} {v}" for k, v in
                                                                          trigger.counts.items()))
            presence.close()
            for s in (occupancy, state):
                s.undeclare()
            demo_sub.undeclare()
            if person is not None:
                person[1].undeclare()

    def _follow_person(self, session: object) -> tuple[PersonBody, object] | None:
        """Real time with a body term: follow the person's poses; ``(the body, its subscription)`` or None.

        Every pose is noted (each demonstration is placed from its first); None when the cost has no body term.
        """
        cost = self.planner.cost
        if not (hasattr(cost, "set_body") and cost.config.body_clearance > 0):  # the toy costs of tests have none
            return None
        person = PersonBody(self.scene)

        def on_pose(msg: HumanPose) -> None:
            person.note_pose(msg.demo_id, msg.index, msg.features, msg.stamp)

        return person, subscribe(session, self.keys.pose, HumanPose, on_pose, self.rejects, self.receipt)

    def _note_body(self, person: PersonBody) -> None:
        """Hand the newest pose's body to the cost, once per pose (a bad one is logged, the last good one kept)."""
        seen = person.poses_
        if seen == self._body_poses:
            return
        capsules = person.capsules()
        if capsules is None:
            return
        try:
            self.planner.cost.set_body(*capsules)
        except ValueError as exc:
            log.error("planner: the person's pose at %.3f s gives no body to keep clear of: %s", person.stamp_, exc)
        self._body_poses = seen


def occupancy_identity(msg: OccupancyGrid | None) -> tuple[int, int, int, float] | None:
    """What tells two predictions apart: ``(demo_id, tick, index, stamp)`` (None: no prediction)."""
    if msg is None:
        return None
    return (msg.demo_id, msg.tick, msg.index, msg.stamp)
