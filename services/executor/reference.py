"""The trajectory the executor follows: one plan's chosen waypoints as a function of time or of path length."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["Reference"]


class Reference:
    """The chosen trajectory of one plan as a piecewise-linear function of its own clock or of its length.

    Args:
        waypoints: ``(T, D)`` configurations ``dt`` seconds apart (already clamped to the limits).
        dt: Waypoint spacing, seconds.
        weights: ``(D,)`` per-joint weights of the length (None: 1 each).

    Attributes:
        cumulative: ``(T,)`` configuration-space length (the weighted joint-space Euclidean norm) from the first
            waypoint to each waypoint; ``length``: its last value.
    """

    def __init__(self, waypoints: np.ndarray, dt: float, weights: np.ndarray | None = None) -> None:
        self.waypoints = waypoints
        self.dt = float(dt)
        self.duration = self.dt * (len(waypoints) - 1)
        steps = np.diff(waypoints, axis=0) * (1.0 if weights is None else np.asarray(weights, dtype=np.float64))
        seg = np.linalg.norm(steps, axis=-1) if len(waypoints) > 1 else np.zeros(0)
        self.cumulative = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.cumulative[-1])

    def at_length(self, s: float) -> np.ndarray:
        """``(D,)`` the configuration ``s`` along the path (configuration-space length; held at the ends)."""
        if s <= 0.0 or self.length <= 0.0:
            return self.waypoints[0].copy() if s <= 0.0 else self.waypoints[-1].copy()
        if s >= self.length:
            return self.waypoints[-1].copy()
        i = int(np.searchsorted(self.cumulative, s, side="right")) - 1
        i = min(max(i, 0), len(self.waypoints) - 2)
        span = self.cumulative[i + 1] - self.cumulative[i]
        a = (s - self.cumulative[i]) / span if span > 0 else 0.0
        return (1.0 - a) * self.waypoints[i] + a * self.waypoints[i + 1]

    @property
    def goal(self) -> np.ndarray:
        """``(D,)`` last waypoint."""
        return self.waypoints[-1]

    def at(self, tau: float) -> np.ndarray:
        """``(D,)`` reference configuration ``tau`` seconds after the trajectory's start (held at the ends)."""
        if tau <= 0.0 or len(self.waypoints) == 1:
            return self.waypoints[0].copy()
        if tau >= self.duration:
            return self.waypoints[-1].copy()
        x = tau / self.dt
        i = min(int(math.floor(x)), len(self.waypoints) - 2)  # tau just below duration may round to the last index
        a = x - i
        return (1.0 - a) * self.waypoints[i] + a * self.waypoints[i + 1]
