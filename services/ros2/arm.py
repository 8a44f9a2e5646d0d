"""The executor's arm when the robot is a ROS 2 robot (``robot = "ros2"``): the same rules, a real robot's motion.

Pure (no Zenoh): :class:`Ros2Arm` is :class:`services.executor.core.ExecutorCore` -- the same plan adoption,
hold rules, reference and its pace -- whose configuration is measured rather than simulated. Through a
:class:`RobotLink` (the executor's Zenoh side, :mod:`services.ros2.link`) it

* sends the adopted plan to the robot's ``joint_trajectory_controller`` once, as the rest of the reference
  from where the executor's pace has got to, timed at that pace and within ``velocity_scale`` of the
  joint velocity limits (:func:`command_points`); again after a hold ends;
* sends a hold when the robot must hold (:meth:`ExecutorCore.stale_reason`, plus the robot's own joint
  states going stale): one point where the arm is now (:func:`hold_point`). Not a trajectory without points:
  ros2_controllers' JointTrajectoryController refuses that ("Empty trajectory received.") and goes on with
  the trajectory it has;
* reads the robot's configuration and velocity back after each step (lock-step: the state the robot
  reports at the step's simulated time, which it follows on ``/clock``; real time: the newest one). A
  continuous joint (the PR2's forearm and wrist roll) reported unwrapped (2 pi + 0.1) is wrapped into the
  planner's [-pi, pi) (it was clamped to pi, up to pi off); commands turn it the short way from the robot's
  own reading (:meth:`ArmLimits.unwrap_from`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from services.executor.config import ExecutorConfig
from services.executor.core import ArmLimits, ExecutorCore
from services.executor.reference import Reference

__all__ = ["Measured", "RobotLink", "Ros2Arm", "command_points", "hold_point", "present", "MIN_SEGMENT_S"]

MIN_SEGMENT_S = 1e-3
"""Shortest time between two points of a command (a controller needs strictly increasing times)."""


@dataclass(frozen=True)
class Measured:
    """The robot's state as it reported it: ``q``, ``qd`` ``(D,)``; ``age_s`` since it arrived (0 in lock-step)."""

    q: np.ndarray
    qd: np.ndarray
    age_s: float = 0.0


class RobotLink(Protocol):
    """How :class:`Ros2Arm` talks to the robot (:class:`services.ros2.link.Ros2RobotLink` on rmw_zenoh)."""

    def send(self, positions: np.ndarray, times: np.ndarray) -> None:
        """Command ``(N, D)`` ``positions`` at ``(N,)`` ``times`` from now (seconds, increasing)."""

    def measure(self, t: float) -> Measured:
        """The robot's state at the executor's time ``t`` (lock-step: waits for it; real time: the newest)."""


def command_points(reference: Reference, progress: float, q: np.ndarray, config: ExecutorConfig,
                   limits: ArmLimits) -> tuple[np.ndarray, np.ndarray]:
    """The rest of ``reference`` from ``progress`` on, timed at the executor's pace, for a trajectory controller.

    Args:
        reference: The adopted plan's chosen trajectory.
        progress: How far the executor's pace has got along it: seconds, or configuration-space length with
            ``config.path_per_step``.
        q: ``(D,)`` the robot's present configuration in its own joint values, a continuous joint possibly
            unwrapped (where the controller starts from: :func:`present`, not its last report).
        config: ``path_per_step``, ``step_period_s``, ``velocity_scale``.
        limits: The joint velocity limits, and which joints are continuous.

    Returns:
        ``positions`` ``(N, D)``: the waypoints still ahead (at least the last one), in the robot's own joint values
        (continuous joints turning the short way from ``q``: :meth:`ArmLimits.unwrap_from`); ``times`` ``(N,)``:
        their ``time_from_start``, each segment at least as long as the slowest joint needs at ``velocity_scale``
        of its limit, and :data:`MIN_SEGMENT_S`. The segments are timed on the unwrapped positions: a wrist roll
        at +pi read as -pi was timed as a turn of 2 pi the long way round (9x slower than needed).
    """
    if config.path_per_step > 0:
        ahead = reference.cumulative > progress + 1e-12
        nominal = (reference.cumulative - progress) * config.step_period_s / config.path_per_step
    else:
        ahead = reference.dt * np.arange(len(reference.waypoints)) > progress + 1e-12
        nominal = reference.dt * np.arange(len(reference.waypoints)) - progress
    ahead[-1] = True
    positions = limits.unwrap_from(q, reference.waypoints[ahead])
    nominal = np.maximum(nominal[ahead], 0.0)
    start = np.vstack([np.asarray(q, dtype=np.float64)[None], positions[:-1]])
    slowest = np.max(np.abs(positions - start) / (limits.velocity * config.velocity_scale), axis=-1)  # (N,)
    segments = np.maximum(np.maximum(np.diff(nominal, prepend=0.0), slowest), MIN_SEGMENT_S)
    return positions.copy(), np.cumsum(segments)


def present(measured: Measured, limits: ArmLimits, since_s: float = 0.0) -> np.ndarray:
    """``(D,)`` where the arm is now, in the robot's own joint values: its report moved on by ``qd`` over its age.

    ``since_s``: seconds since the report was read (its age then was ``age_s``). The bounded joints are kept within
    their limits. A command timed from the report itself was short by the distance the arm had moved since (a
    lagging test robot: 1.5 rad/s against a 1 rad/s limit; the simulated PR2 went 4-7 rad/s in the first 15-25 ms
    of new plans, limits 2.3-3.6, of which this removes part: docs/ros2.md).
    """
    bounded = ~limits.continuous_mask
    now = measured.q + measured.qd * (measured.age_s + since_s)
    now[bounded] = np.clip(now[bounded], limits.lower[bounded], limits.upper[bounded])
    return now


def hold_point(measured: Measured, limits: ArmLimits, velocity_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The hold command: one point where the arm is now (:func:`present`), in the robot's own joint values.

    Args:
        measured: The robot's last report; the arm has moved on by ``qd`` over its ``age_s`` since (0 in lock-step).
        limits: The joints' limits (the bounded joints' point is kept within them) and velocities.
        velocity_scale: The share of the velocity limits the arm may use to get there.

    Returns:
        ``positions`` ``(1, D)``; ``times`` ``(1,)``: the time the slowest joint needs at ``velocity_scale`` from
        the reported configuration, at least :data:`MIN_SEGMENT_S`.
    """
    target = present(measured, limits)
    slowest = float(np.max(np.abs(target - measured.q) / (limits.velocity * velocity_scale)))
    return target[None], np.array([max(slowest, MIN_SEGMENT_S)])


class Ros2Arm(ExecutorCore):
    """:class:`ExecutorCore`'s rules driving a ROS 2 robot through ``link``; ``q``/``qd`` are the robot's.

    Args:
        limits: The arm's joints and limits (the commands' joint order).
        q0: ``(D,)`` the robot's configuration at the start (as it reported it).
        config: The executor's options (``stale_limit_s`` also bounds the age of the robot's joint states).
        link: The robot.
        guard: The separation guard (:class:`ExecutorCore`), asked before the robot is commanded.
    """

    def __init__(self, limits: ArmLimits, q0: np.ndarray, config: ExecutorConfig, link: RobotLink,
                 guard: Callable[[np.ndarray, np.ndarray], str] | None = None) -> None:
        super().__init__(limits, q0, config, guard)
        self.link = link
        self.sent_plans = 0
        self.sent_holds = 0
        self._commanded: object = None  # the plan last sent, or None while holding (or before any plan)
        self._state_age = 0.0
        self._measured = Measured(np.asarray(q0, dtype=np.float64).copy(), np.zeros(limits.dof))  # the robot's own
        self.q = limits.clamp(limits.wrap(q0))

    def stale_reason(self, t: float | None = None) -> str:
        """The executor's reasons, and the robot's joint states older than ``stale_limit_s`` (real time)."""
        reason = super().stale_reason(t)
        if not reason and self._state_age > self.config.stale_limit_s:
            return f"robot's joint states are {self._state_age:.2f} s old (limit {self.config.stale_limit_s:.2f} s)"
        return reason

    def step(self, h: float, hold_reason: str | None = None) -> None:
        """Command the robot for the next ``h`` seconds (the plan, once, or a hold), then read its state back."""
        reason = self.stale_reason() if hold_reason is None else hold_reason
        if not reason and self.reference is not None and self.guard is not None:
            # the separation guard (real time) is asked before the robot is commanded: it moves on its own once sent
            reason = self.guard(self.q, self.target_after(h))
        if not reason and self.reference is not None:
            if self._commanded is not self.plan:
                # where the arm is, not its report: read at the end of the last step, h ago in real time (in lock-step
                # the arm moves only with the next /clock)
                since = h if self.config.mode == "realtime" else 0.0
                now = present(self._measured, self.limits, since)  # the robot's own values, bounded ones clamped
                self.link.send(*command_points(self.reference, self.tau, now, self.config, self.limits))
                self._commanded = self.plan
                self.sent_plans += 1
        elif self._commanded is not None:  # hold where it is, once per hold (nothing was sent before a plan)
            self.link.send(*hold_point(self._measured, self.limits, self.config.velocity_scale))
            self._commanded = None
            self.sent_holds += 1
        super().step(h, reason)  # the pace (tau), the clock, holding and its reason; its simulated q is replaced:
        measured = self._measured = self.link.measure(self.t)
        self.q, self.qd = self.limits.clamp(self.limits.wrap(measured.q)), measured.qd
        self._state_age = measured.age_s
        self._update_reached()
