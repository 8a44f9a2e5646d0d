"""The executor's real-time loop: the arm follows the newest plan from the moment it arrives, on the wall clock.

After the wait for the ``wait_for`` services the run's clock starts; every ``1 / state_rate_hz`` s of wall time
the core adopts the newest plan (it counts as received now, and the arm takes it over from the reference it follows:
:mod:`services.executor.splice`), notes the newest prediction's arrival, advances by the wall time elapsed and
publishes a RobotState. No clock ticks go out. The state is stamped with the wall time its ``q`` is for: the run's
start on the wall clock plus the core's time (the monotonic seconds since then). Stamped with the wall clock after
the step, a state's stamp lagged its ``q`` by however long the step took (the guard's forward kinematics, other
threads): stamps 1-91 ms apart for 20 ms steps, and ``q`` differenced over them gave 2.28 rad/s where ``qd`` was
about 0.2 (a review).

The run lasts ``steps x step_period_s`` seconds. With ``finish_s`` it may go on after that, adopting plans as
before, until the robot reaches its goal, at most ``finish_s`` more seconds: the real-time counterpart of
lock-step's ``finish_path`` (a lock-step run executes the rest of its last plan after its last step; a real-time
run ended where the robot was, short of the cup, at the demo's pace). ``stop_on_goal`` ends it at the goal
earlier still.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Any

from shared.lockstep import Adoption
from shared.transport import Presence, TypedPublisher

from .core import ExecutorCore, reason_kind

if TYPE_CHECKING:
    from .service import ExecutorService

__all__ = ["run_realtime", "advance"]

log = logging.getLogger("foresight.executor")


def advance(core: ExecutorCore, gap: float, h_max: float) -> None:
    """Simulate ``gap`` seconds in steps of at most ``h_max``, each judged for staleness (and the guard) at its start.

    After a stall of the loop (2 s: a busy machine, a debugger) one step of the whole gap was one straight move in
    joint space on a plan 2.2 s old, cutting the plan's bends (0.25 rad off an L-shaped path; a review): walked in
    state periods, the arm follows the path and holds once the plan is stale, as it would have without the stall.
    """
    while gap > 1e-9:
        h = min(gap, h_max)
        core.step(h)
        gap -= h


def run_realtime(svc: ExecutorService, state_pub: TypedPublisher[Any], presence: Presence) -> None:
    """Run ``svc``'s robot in real time until the run's end, the goal (``finish_s``, ``stop_on_goal``) or a stop."""
    cfg, core, result = svc.config, svc.core, svc.result
    svc.wait_for_peers(presence)  # the run's clock starts once the planner (and the rest) are there
    period = cfg.step_period_s
    h_nom = 1.0 / cfg.state_rate_hz
    end = cfg.steps * period if cfg.steps else float("inf")
    t0, wall0 = time.monotonic(), time.time()  # the core's clock runs on t0; its time 0 on the wall clock
    adoption = Adoption()
    next_wake = t0
    last_kind = None
    finishing = False
    while not svc.stop.is_set():
        if core.t >= end:
            if core.reached or core.t >= end + cfg.finish_s:
                break
            if not finishing:
                finishing = True
                log.info("executor: the run's %.1f s are over and the robot is not at its goal: it goes on until it "
                         "is, at most %.1f s more (finish_s)", end, cfg.finish_s)
        next_wake += h_nom
        delay = next_wake - time.monotonic()
        if delay > 0:
            svc.stop.wait(delay)
        elif delay < -h_nom:  # behind (a stall): the next state comes a period from now, not at once to catch up
            next_wake = time.monotonic()  # (100 states went out in the same instant after a 2 s stall)
        elapsed = time.monotonic() - t0
        received = svc.inbox.latest()
        plan = adoption.realtime(received)
        if plan is not None:
            core.adopt(plan)  # taken over now (joined, spliced or led in); counts as received now
        if received.occupancy_time is not None:
            core.note_occupancy(received.occupancy_time - t0)
        advance(core, max(elapsed - core.t, 1e-6), 2 * h_nom)
        if core.holding:
            result.held_steps += 1
        if reason_kind(core.reason) != last_kind:  # each change once, not every state (the ages change)
            if core.reason:
                log.info("executor: holding at t=%.2f s: %s", core.t, core.reason)
            elif last_kind is not None:
                log.info("executor: resuming at t=%.2f s", core.t)
            last_kind = reason_kind(core.reason)
        svc.publish_state(state_pub, core.state(-1, wall0 + core.t))  # the wall time its q is for
        step = int(core.t // period)
        while len(result.goal_per_step) < step:
            result.goal_per_step.append(core.goal)
        result.steps = min(step, cfg.steps) if cfg.steps else step
        result.finish_steps = step - result.steps
        if core.reached and result.note_reached(core.goal, step):
            log.info("executor: goal %d reached at t=%.2f s", core.goal, core.t)
            if cfg.stop_on_goal:
                break
