"""A simulated ``joint_trajectory_controller``: the test robot's arm (pure: no Zenoh, no ROS).

What ros2_controllers' JointTrajectoryController does with a ``JointTrajectory`` on its topic, reduced to a
kinematic arm that follows perfectly: a new trajectory replaces the one in progress at once; the arm goes
from where it is to the first point in that point's ``time_from_start`` and on between the points linearly
in time; after the last point it holds it; joints the message does not name keep their position; a trajectory
without points is refused and the one in progress goes on, as the real controller's "Empty trajectory
received." (:meth:`services.ros2.core.Ros2Mapping.trajectory_in` refuses it before it gets here).
Used by ``foresight simrobot`` (:mod:`services.ros2.robot_sim`)
to try ``--robot ros2`` without a robot, and by the tests.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SimulatedController"]


class SimulatedController:
    """A kinematic arm following joint trajectories.

    Args:
        q0: ``(D,)`` the start configuration.

    Attributes:
        q: ``(D,)`` the configuration at the last :meth:`advance`; ``qd`` its velocity; ``t`` its time.
        received: Trajectories accepted so far.
    """

    def __init__(self, q0: np.ndarray) -> None:
        self.q = np.asarray(q0, dtype=np.float64).copy()
        self.qd = np.zeros_like(self.q)
        self.t = 0.0
        self.received = 0
        self._times = np.zeros(1)
        self._knots = self.q[None].copy()  # (K, D): configuration at self._times

    def command(self, t: float, columns: list[int], positions: np.ndarray, times: np.ndarray) -> None:
        """Replace the trajectory at time ``t`` (the arm's own clock: simulated or wall seconds).

        Args:
            t: When it arrived.
            columns: The message's joints as indices of this arm's joints.
            positions: ``(N, len(columns))`` its points.
            times: ``(N,)`` their time from ``t``.
        """
        if not len(positions):  # refused: the trajectory in progress goes on
            return
        here = self.position(t)
        knots = np.repeat(here[None], len(positions) + 1, axis=0)
        knots[1:, columns] = positions
        self._times = np.concatenate([[t], t + np.asarray(times, dtype=np.float64)])
        self._knots = knots
        if len(positions) and times[0] <= 0.0:  # a first point due now: the arm is there now
            self._times, self._knots = self._times[1:], self._knots[1:]
        self.received += 1

    def position(self, t: float) -> np.ndarray:
        """``(D,)`` where the trajectory puts the arm at time ``t`` (held before its start and after its end)."""
        return np.array([np.interp(t, self._times, self._knots[:, j]) for j in range(self._knots.shape[1])])

    def advance(self, t: float) -> None:
        """Move the arm to time ``t`` (its velocity: the mean over the interval)."""
        q = self.position(t)
        dt = t - self.t
        self.qd = (q - self.q) / dt if dt > 0 else np.zeros_like(q)
        self.q, self.t = q, t
