"""The executor's real-time loop: the arm follows the newest plan from the moment it arrives, on the wall clock.

After the wait for the ``wait_for`` services the run's clock starts; every ``1 / state_rate_hz`` s of wall time
the core adopts the newest plan (it counts as received now), notes the newest prediction's arrival, advances
by the wall time elapsed and publishes a RobotState. No clock ticks go out.

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

from .core import reason_kind

if TYPE_CHECKING:
    from .service import ExecutorService

__all__ = ["run_realtime"]

log = logging.getLogger("foresight.executor")


def run_realtime(svc: ExecutorService, state_pub: TypedPublisher[Any], presence: Presence) -> None:
    """Run ``svc``'s robot in real time until the run's end, the goal (``finish_s``, ``stop_on_goal``) or a stop."""
    cfg, core, result = svc.config, svc.core, svc.result
    svc.wait_for_peers(presence)  # the run's clock starts once the planner (and the rest) are there
    period = cfg.step_period_s
    h_nom = 1.0 / cfg.state_rate_hz
    end = cfg.steps * period if cfg.steps else float("inf")
    t0 = time.monotonic()
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
        elapsed = time.monotonic() - t0
        received = svc.inbox.latest()
        plan = adoption.realtime(received)
        if plan is not None:
            core.adopt(plan)  # starts now; counts as received now
        if received.occupancy_time is not None:
            core.note_occupancy(received.occupancy_time - t0)
        core.step(max(elapsed - core.t, 1e-6))
        if core.holding:
            result.held_steps += 1
        if reason_kind(core.reason) != last_kind:  # each change once, not every state (the ages change)
            if core.reason:
                log.info("executor: holding at t=%.2f s: %s", core.t, core.reason)
            elif last_kind is not None:
                log.info("executor: resuming at t=%.2f s", core.t)
            last_kind = reason_kind(core.reason)
        svc.publish_state(state_pub, core.state(-1, time.time()))
        step = int(core.t // period)
        while len(result.goal_per_step) < step:
            result.goal_per_step.append(core.goal)
        result.steps = min(step, cfg.steps) if cfg.steps else step
        result.finish_steps = step - result.steps
        if core.reached and result.note_reached(core.goal, step):
            log.info("executor: goal %d reached at t=%.2f s", core.goal, core.t)
            if cfg.stop_on_goal:
                break
