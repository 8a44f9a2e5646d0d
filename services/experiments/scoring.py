"""One run of ``foresight eval interference`` scored: Table I's integral, its parts, and the real human.

The integral penetration of the executed path against the final prediction (over time, or along the path's
configuration-space length in the paper protocol), the parts of it accrued once at the goal and before the human's
class was recognised, and the robot body's clearance to the human who was really there
(:mod:`services.experiments.measures`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from shared.clearance import body_clearance
from shared.scene import Scene

from .harness import RunRecord
from .measures import contact_summary, interference_along_path, interference_over_time, postures_at

__all__ = ["RunScore", "score_run", "executed_belief"]


@dataclass(frozen=True)
class RunScore:
    """The measures of one run.

    Attributes:
        demo: Index of the demonstration within its class; ``seed``: the run's STOMP seed.
        planner: Variant name (:data:`services.experiments.planners.VARIANTS`).
        interference: Integral penetration of the final prediction (probability-voxels x s).
        interference_at_goal: The part of it accrued from the first state at its goal on (holding there, or
            moving off it again: both count).
        interference_unrecognised: The part accrued during steps planned with a prediction in which the
            human's true class had probability < 0.5 (not yet recognised).
        min_clearance: Smallest robot-body clearance to the real human (m).
        time_in_contact: Seconds with clearance <= 0; ``time_near``: seconds within 5 cm.
        reached_step: First step at which the robot was at its goal (None: never).
        goals: The goal chosen at each step.
        planning_ms: Median planning time of a step.
        borrowed: Scored from basic STOMP's run of the first demonstration (:mod:`services.experiments.reuse`).
    """

    demo: int
    seed: int
    planner: str
    interference: float
    interference_at_goal: float
    interference_unrecognised: float
    min_clearance: float
    time_in_contact: float
    time_near: float
    reached_step: int | None
    goals: tuple[str, ...]
    planning_ms: float
    borrowed: bool = False


def score_run(rec: RunRecord, robot: Any, scene: Scene, final: Any, demo: int, seed: int, planner: str,
              label: int, path_weights: np.ndarray | None = None) -> RunScore:
    """Score one run against the final prediction ``final`` and the streamed human of class ``label``.

    ``path_weights`` given: Table I's integral is along the path's configuration-space length with these
    per-joint weights (the paper protocol, :func:`~services.experiments.measures.interference_along_path`);
    None: over time.
    """
    q, t = rec.q(), rec.stamps()
    contact = contact_summary(body_clearance(robot, q, postures_at(rec.poses, t, scene)), t)
    res = rec.result
    reached = res.reached_step if res is not None and res.reached and res.reached_step >= 0 else None
    per_state = (interference_over_time(robot, q, t, final) if path_weights is None
                 else interference_along_path(robot, q, final, weights=path_weights))
    at_goal = np.array([s.reached for s in rec.states], dtype=bool)
    at_goal = np.maximum.accumulate(at_goal) if len(at_goal) else at_goal  # from the first state at the goal on
    unknown = np.array([p < 0.5 for p in executed_belief(rec, label)], dtype=bool)
    return RunScore(demo, seed, planner, float(per_state.sum()), float(per_state[at_goal].sum()),
                    float(per_state[unknown].sum()), contact.min_clearance, contact.time_in_contact, contact.time_near,
                    reached,
                    tuple(rec.chosen_goals()),
                    float(np.median([p.planning_ms for p in rec.plans])) if rec.plans else math.nan)


def executed_belief(rec: RunRecord, label: int) -> list[float]:
    """Per state, the probability of class ``label`` in the prediction the plan it executes was made with.

    In lock-step the robot executes plan n - 1 during step n (:mod:`shared.lockstep`), and that plan was made
    with the grid of its ``occupancy_tick`` (n - 2); after the last step (the rest of the path, paper protocol)
    the last plan. 0 before the first plan and for a plan made before any prediction.
    """
    belief = {t: float(p.posterior[label]) for t, p in rec.posteriors.items()}
    ticks = [p.tick for p in rec.plans]  # in tick order
    out = []
    for s in rec.states:
        i = bisect.bisect_right(ticks, s.tick - 1) - 1  # the newest plan of tick <= n - 1
        out.append(belief.get(rec.plans[i].occupancy_tick, 0.0) if i >= 0 else 0.0)
    return out
