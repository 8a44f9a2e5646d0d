"""Basic STOMP planned once per seed: its executed path does not depend on the human.

Basic STOMP costs the human with ``w_human = 0`` (:mod:`services.experiments.planners`), and a lock-step
run is deterministic, so its executed path is the same whichever demonstration streams. Table I and the
pace sweep score it against each of their demonstrations; rather than plan that path once per
demonstration, :func:`services.experiments.interference.run_interference` runs every planner on every
demonstration at the first seed and checks here, to the bit, that basic STOMP's runs agree
(:func:`same_robot`) and that the human side of a basic run equals that of the least-penetration run of
the same demonstration and seed (:func:`same_human`: both stream the same demonstration to the same
predictor method). Where both hold, each later seed runs basic STOMP on the first demonstration only and
scores it against every demonstration with :func:`with_human`: the robot side of that run, the human side
(poses, posteriors, grids) of the demonstration's least-penetration run. Where either check fails, every
run is made, as before. The saving: 36 of Table I's 150 runs per library and protocol.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from shared.protocol import encode

from .harness import RunRecord

__all__ = ["same_robot", "same_human", "with_human", "first_differing_state"]


def _same_plans(a: RunRecord, b: RunRecord) -> bool:
    """The same plans, but for their planning time (a wall-clock measure)."""
    if len(a.plans) != len(b.plans):
        return False
    return all(encode(dataclasses.replace(p, planning_ms=0.0)) == encode(dataclasses.replace(q, planning_ms=0.0))
               for p, q in zip(a.plans, b.plans, strict=True))


def same_robot(a: RunRecord, b: RunRecord) -> bool:
    """Whether two runs planned and executed the same: every plan (but its timing), state and the outcome."""
    if len(a.states) != len(b.states) or (a.result is None) != (b.result is None):
        return False
    if a.result is not None and b.result is not None and (
            a.result.reached, a.result.reached_step, a.result.goal_per_step, a.result.finish_steps) != (
            b.result.reached, b.result.reached_step, b.result.goal_per_step, b.result.finish_steps):
        return False
    return _same_plans(a, b) and all(encode(s) == encode(t) for s, t in zip(a.states, b.states, strict=True))


def same_human(a: RunRecord, b: RunRecord) -> bool:
    """Whether two runs saw the same human: the same poses, posteriors and grids, tick for tick."""
    if len(a.poses) != len(b.poses) or a.posteriors.keys() != b.posteriors.keys() \
            or a.occupancy.keys() != b.occupancy.keys():
        return False
    return (all(encode(p) == encode(q) for p, q in zip(a.poses, b.poses, strict=True))
            and all(encode(a.posteriors[t]) == encode(b.posteriors[t]) for t in a.posteriors)
            and all(encode(a.occupancy[t]) == encode(b.occupancy[t]) for t in a.occupancy))


def with_human(robot: RunRecord, human: RunRecord) -> RunRecord:
    """The record of ``robot``'s run had ``human``'s demonstration streamed (see the module docstring).

    Args:
        robot: A basic STOMP run: its plans, states and outcome are kept.
        human: A run of the demonstration to score against: its poses, posteriors and grids are kept.
    """
    return RunRecord(plans=robot.plans, states=robot.states, poses=human.poses, occupancy=human.occupancy,
                     posteriors=human.posteriors, result=robot.result)


def first_differing_state(a: RunRecord, b: RunRecord) -> float | None:
    """The stamp of the first state at which two runs' configurations differ, or at which the shorter ends.

    None: the same configurations at the same number of states.
    """
    for s, t in zip(a.states, b.states, strict=False):
        if not np.array_equal(s.q, t.q):
            return float(s.stamp)
    if len(a.states) == len(b.states):
        return None
    shorter = min(a.states, b.states, key=len)
    return float(shorter[-1].stamp) if shorter else 0.0
