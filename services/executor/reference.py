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
        self.weights = None if weights is None else np.asarray(weights, dtype=np.float64)
        self.duration = self.dt * (len(waypoints) - 1)
        steps = np.diff(waypoints, axis=0) * (1.0 if self.weights is None else self.weights)
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

    def length_at(self, tau: float) -> float:
        """The configuration-space length from the start to the point ``tau`` seconds on (held at the ends)."""
        if tau <= 0.0 or len(self.waypoints) == 1:
            return 0.0
        if tau >= self.duration:
            return self.length
        x = tau / self.dt
        i = min(int(math.floor(x)), len(self.waypoints) - 2)
        return float(self.cumulative[i] + (x - i) * (self.cumulative[i + 1] - self.cumulative[i]))

    def time_at_length(self, s: float) -> float:
        """Seconds from the start to the first point ``s`` along the path (held at the ends: :meth:`at_length`)."""
        if s <= 0.0:
            return 0.0
        if s >= self.length:
            return self.duration
        i = int(np.searchsorted(self.cumulative, s, side="right")) - 1
        i = min(max(i, 0), len(self.waypoints) - 2)
        span = self.cumulative[i + 1] - self.cumulative[i]
        return float((i + ((s - self.cumulative[i]) / span if span > 0 else 0.0)) * self.dt)

    def project(self, q: np.ndarray, start: float, end: float) -> float:
        """Seconds from the start to the point of the path between ``start`` and ``end`` s nearest ``q`` ``(D,)``.

        In the length's weighted metric; of the points as near as the nearest (to 1e-6) the first is taken. Both
        bounds are held at the path's end.
        """
        end = min(end, self.duration)
        start = min(start, end)
        inner = self.dt * np.arange(len(self.waypoints))
        ts = np.concatenate([[start], inner[(inner > start) & (inner < end)], [end]])
        i, a = _closest_on(np.array([self.at(t) for t in ts]), q, self.weights)
        return float(ts[i] + a * (ts[i + 1] - ts[i]))

    def nearest(self, q: np.ndarray, within: float, by_length: bool = False) -> float:
        """Where the point of the path nearest ``q`` ``(D,)`` lies: seconds from its start, or length (``by_length``).

        A plan may reach a real-time executor later than the planner expected (waypoint 0 is where the robot was to be
        a planning time on, or where it was at its state's stamp): the robot is already past its start, and the arm
        joins the path there instead of being driven back to it. Only the segments that begin within ``within`` of
        the start are searched (a path that comes back near itself later is not joined there), in the length's
        weighted metric, and of the points as near as the nearest (to 1e-6) the first is taken: a plan that waits at
        its start is not skipped.
        """
        w = self.waypoints
        if len(w) < 2:
            return 0.0
        starts = self.cumulative[:-1] if by_length else self.dt * np.arange(len(w) - 1)
        n = max(1, int(np.count_nonzero(starts < within)))
        i, a = _closest_on(w[:n + 1], q, self.weights)
        if by_length:
            return float(self.cumulative[i] + a * (self.cumulative[i + 1] - self.cumulative[i]))
        return float((i + a) * self.dt)


def _closest_on(points: np.ndarray, q: np.ndarray, weights: np.ndarray | None) -> tuple[int, float]:
    """The segment of the polyline ``points`` ``(N, D)`` nearest ``q`` ``(D,)`` and the fraction along it.

    In the weighted metric of the path's length; of the points as near as the nearest (to 1e-6) the first is taken,
    and a segment of no length is at its start.
    """
    k = 1.0 if weights is None else weights
    d = np.diff(points, axis=0) * k
    r = (np.asarray(q, dtype=np.float64) - points[:-1]) * k
    dd = np.sum(d * d, axis=-1)
    a = np.clip(np.sum(r * d, axis=-1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    dist = np.linalg.norm(r - a[:, None] * d, axis=-1)
    i = int(np.argmax(dist <= dist.min() + 1e-6))
    return i, float(a[i])
