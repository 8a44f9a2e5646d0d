"""How a real-time arm takes over a new plan from the reference it is following (:meth:`ExecutorCore.adopt`).

In real time the planner plans from where the robot will be one planning time on: along its previous plan, or, off
it, the robot's state moved on by its velocity. A plan that arrives later than that starts behind the arm, one that
arrives earlier starts ahead of it. :func:`take_over` makes one :class:`Reference` of the new plan, and the arm's
progress on it:

* **joined**: the arm is past the plan's start: it joins the plan at its point nearest the arm
  (:meth:`Reference.nearest`) instead of being driven back to waypoint 0. Where that point is off the arm (a plan
  that leaves the arm's path: 0.03-0.05 rad in a review's real-time runs), the arm goes straight to the plan's next
  waypoint at the plan's pace, as a lead-in (below), instead of closing the gap at its velocity limits;
* **spliced**: waypoint 0 lies on the reference the arm is following, ahead of it (within ``stale_limit_s`` of its
  progress, and every joint within ``goal_tolerance`` of it): the arm goes on along that reference to its point
  nearest waypoint 0, then along the plan, as a motion controller splices trajectories. Before, it went straight
  to waypoint 0 at the velocity limits: up to 0.93 of them for one state where every plan was timed at 0.1
  (21 of 131 plans started 0.003-0.042 rad ahead; a review);
* **led in**: otherwise (no reference yet, a plan that leaves in another direction, an arm off its path): a straight
  lead-in from the arm to waypoint 0 at the plan's own pace (its fastest joint's share of the limits, or
  ``velocity_scale`` for a plan at rest), faster only where that pace would take longer than ``stale_limit_s``
  (a plan's life), and never faster than ``velocity_scale`` allows.

The lead (the rest of the old reference, or the lead-in) is sampled at the plan's ``dt`` before its waypoint 0, so
the result is one evenly timed reference: what the arm follows, and what a ROS 2 robot is sent
(:func:`services.ros2.arm.command_points`). The published goal is the new plan's from its adoption on: the arm is
committed to it, its lead included.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import ExecutorConfig
from .reference import Reference

__all__ = ["Takeover", "take_over", "pace", "JOIN_ON_PATH"]

JOIN_ON_PATH = 1e-6
"""A late plan's point nearest the arm within this of it (every joint, rad or m) is on the arm: followed from there."""


@dataclass(frozen=True)
class Takeover:
    """A new plan as the arm takes it over: ``reference`` to follow, ``progress`` on it, ``how`` it was taken over.

    ``progress`` is seconds, or configuration-space length with ``path_per_step``; ``how`` is ``"joined"``,
    ``"spliced"`` or ``"led in"``.
    """

    reference: Reference
    progress: float
    how: str


def pace(reference: Reference, velocity: np.ndarray) -> float:
    """The fastest joint speed of ``reference`` as a share of that joint's ``(D,)`` ``velocity`` limit (0: at rest)."""
    if len(reference.waypoints) < 2:
        return 0.0
    return float(np.max(np.abs(np.diff(reference.waypoints, axis=0)) / (reference.dt * velocity)))


def take_over(new: Reference, q: np.ndarray, current: Reference | None, progress: float, config: ExecutorConfig,
              velocity: np.ndarray) -> Takeover:
    """The reference the arm follows from now on, and its progress on it (real time; the module's three cases).

    Args:
        new: The new plan's chosen trajectory (clamped into the joint limits).
        q: ``(D,)`` the arm's configuration.
        current: The reference the arm is following, or None before the first plan.
        progress: The arm's progress along ``current``: seconds, or length with ``config.path_per_step``.
        config: ``stale_limit_s``, ``goal_tolerance``, ``velocity_scale``, ``path_per_step``, ``step_period_s``.
        velocity: ``(D,)`` the joint velocity limits.
    """
    rate = config.path_per_step / config.step_period_s  # length per second of the paper authors' pace (0: in time)
    by_length = rate > 0
    within = config.stale_limit_s * rate if by_length else config.stale_limit_s
    fastest = velocity * config.velocity_scale
    share = pace(new, velocity)
    lead_speed = velocity * min(share, config.velocity_scale) if share > 0 else fastest

    def lead_s(gap: np.ndarray) -> float:  # the time to close gap at the plan's pace, within its life if it can be
        return max(float(np.max(np.abs(gap) / fastest)),
                   min(float(np.max(np.abs(gap) / lead_speed)), config.stale_limit_s))

    q = np.asarray(q, dtype=np.float64)
    joined = new.nearest(q, within, by_length)
    if joined > 0.0:
        on = new.at_length(joined) if by_length else new.at(joined)
        if float(np.max(np.abs(on - q))) <= JOIN_ON_PATH:
            return Takeover(new, joined, "joined")
        # off the plan: led to its next waypoint at its pace (the waypoints behind the arm are dropped)
        nxt = int(np.searchsorted(new.cumulative, joined, side="right")) if by_length else int(joined / new.dt) + 1
        rest = Reference(new.waypoints[min(nxt, len(new.waypoints) - 1):], new.dt, new.weights)
        gap = rest.waypoints[0] - q
        return _led(rest, lambda u: q + u * gap, lead_s(gap), by_length, "joined")
    w0 = new.waypoints[0]
    if current is not None:
        start = min(current.time_at_length(progress) if by_length else progress, current.duration)
        end = current.time_at_length(progress + within) if by_length else start + within
        s = current.project(w0, start, end)
        gap = w0 - current.at(s)
        if float(np.max(np.abs(gap))) <= config.goal_tolerance:
            return _led(new, lambda u: current.at(start + u * (s - start)) + u * gap,
                        max(s - start, lead_s(gap)), by_length, "spliced")
    gap = w0 - q
    return _led(new, lambda u: q + u * gap, lead_s(gap), by_length, "led in")


def _led(new: Reference, curve: Callable[[float], np.ndarray], lead: float, by_length: bool, how: str) -> Takeover:
    """``new`` after ``lead`` seconds of ``curve`` (``u``: 0 where the arm's reference is now, 1 at waypoint 0).

    The lead's points lie ``new.dt`` apart in time, the last one ``dt`` before waypoint 0; the first is moved along
    the line through the arm's point and the next so that the reference passes through the arm's point at the
    progress returned (it lies behind the arm: never followed, nor sent to a robot).
    """
    if lead <= 1e-9:
        return Takeover(new, 0.0, how)
    dt = new.dt
    n = max(1, math.ceil(lead / dt - 1e-9))
    u = 1.0 - dt * np.arange(n, 0, -1) / lead  # u[0] <= 0 (the arm's point at 0 lies in the first segment)
    points = [curve(float(x)) for x in u]
    here = curve(0.0)
    after, u_after = (points[1], u[1]) if n > 1 else (new.waypoints[0], 1.0)
    points[0] = here + (after - here) * (u[0] / u_after)
    reference = Reference(np.vstack([np.array(points), new.waypoints]), dt, new.weights)
    tau = max(n * dt - lead, 0.0)
    return Takeover(reference, reference.length_at(tau) if by_length else tau, how)
