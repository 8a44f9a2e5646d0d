"""The output of one replanning step (:meth:`services.planner.core.Planner.step`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["PlanResult"]


@dataclass
class PlanResult:
    """One replanning step's output (numpy, on the host).

    Attributes:
        step: Replanning step index (0 for the first).
        goal_names: K names; joint_names: D names.
        trajectories: ``(K, T, D)`` float32 trajectories, all starting at ``start`` and within the
            limits; an invalid goal's trajectory holds ``start``.
        cost_smoothness, cost_obstacle, cost_human, cost_total: ``(K,)`` float64 (inf where invalid).
        valid: ``(K,)`` bool.
        chosen: Index of tau_best (a valid goal).
        dt: Seconds between waypoints of the chosen trajectory (velocity limits x ``velocity_scale``).
        start: ``(D,)`` the configuration the trajectories start at (q_t).
        planning_ms: Wall time of :meth:`Planner.step`.
        reasons: Why each invalid goal is invalid.
        iterations: STOMP iterations run (``stomp.iterations``, fewer when the anytime option stopped early).
        cost_history: ``(iterations + 1, Kv)`` total cost of each valid goal's current trajectory before each
            iteration and after the last (``StompResult.history``; how fast the step converged).
        off_path: The robot was farther than ``off_path_tol`` from the previous tau_best: every goal was planned
            from its configuration, not reconnected (``Planner.start_configuration``).
    """

    step: int
    goal_names: list[str]
    joint_names: list[str]
    trajectories: np.ndarray
    cost_smoothness: np.ndarray
    cost_obstacle: np.ndarray
    cost_human: np.ndarray
    cost_total: np.ndarray
    valid: np.ndarray
    chosen: int
    dt: float
    start: np.ndarray
    planning_ms: float
    reasons: list[str]
    iterations: int = 0
    cost_history: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    off_path: bool = False
