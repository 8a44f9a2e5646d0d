"""The separation guard: near the person it sees, the robot makes no move that brings it closer (real time).

Beyond the paper. The planner keeps the robot out of where the person is *predicted* to be; where the prediction is
wrong (a motion unlike every class, a reach that leans in), nothing kept the robot from closing in on the person it
could see. The guard is the last check before each simulation step, the separation half of ISO/TS 15066's speed and
separation monitoring: once the clearance between the robot's collision spheres and the person's body (the human
model's capsules, posed by the ``HumanPose``s of the last ``window_s`` and placed as the predictor places them; the
nearest counts) is under ``stop_m``, a step that would shrink it is not taken; the robot holds
(``RobotState.reason`` says so) and moves again as soon as its next step keeps or widens the clearance: the person
stepped back, or the plan leads away from them. docs/executor.md says what it does not see.

Real time only. A lock-step run is a measurement of the planners (the experiments and ``foresight demo`` compare
their contact with the human), which a guard stopping the robot would hide; its human is a recording.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from shared.clearance import sphere_capsule_clearance, sphere_centres
from shared.human import HumanModel, StreamPlacement

from .config import SEPARATION_REASON, ExecutorConfig, SeparationConfig

__all__ = ["SeparationGuard", "separation_guard"]


MAX_STEP_RAD = 0.02
"""The longest joint move (rad, or m for the torso) between two configurations the guard checks along one step: a
step the loop made long (a stall) is checked at points this far apart, so it cannot jump across a body (at the end
of a 1 m lever, 2 cm)."""

MAX_POINTS = 50
"""At most this many configurations checked along one step (1 rad of the longest joint's move)."""


class SeparationGuard:
    """Decides, before each simulation step, whether the step would close in on the person.

    The person is where any pose of the last ``window_s`` puts them: the step is judged against the nearest of those
    bodies, so a noisy pose that shows the person further away lets the robot no nearer (a review: against the newest
    pose alone, the robot advanced whenever noise moved the person back, and with 0.05 rad of noise on the joint
    angles walked into the body).

    Args:
        config: Its options.
        robot: The robot model (``sphere_centers``, ``sphere_radii``; the executor's joint order).
        scene: The scene the person is placed in (``scene.human``).
        human: The human model (default: a new :class:`HumanModel`).

    Attributes:
        clearance_: The robot's clearance to the nearest body of the window at the last check (m; inf before any).
        holds_: Steps the guard held.
    """

    def __init__(self, config: SeparationConfig, robot: Any, scene: Any, human: HumanModel | None = None) -> None:
        self.config = config
        self.robot = robot
        self.human = human or HumanModel()
        self.placement = StreamPlacement(scene)
        self.radii = robot.sphere_radii.double().cpu().numpy()  # (S,)
        self.clearance_ = math.inf
        self.holds_ = 0
        # (stamp, capsule ends (C, 2, 3)) of the poses of the last window_s, and the capsules' radii (C,): replaced
        # whole on each pose (Zenoh's thread), read by the loop's thread
        self._bodies: tuple[tuple[float, np.ndarray], ...] = ()
        self._body_radii = np.zeros(0)

    def note_pose(self, demo_id: int, index: int, features: np.ndarray, stamp: float) -> None:
        """The person's pose at ``stamp`` (s): ``features`` ``(12,)``, the ``index``-th of demonstration ``demo_id``.

        Its body joins those of the last ``window_s``; a stamp before theirs (a new run's clock) starts afresh.
        """
        ends, radii = self.human.capsules(self.placement.place(demo_id, index, features))
        kept = tuple(b for b in self._bodies if stamp - self.config.window_s <= b[0] <= stamp)
        self._body_radii = np.asarray(radii, dtype=np.float64)
        self._bodies = (*kept, (float(stamp), np.asarray(ends, dtype=np.float64)))

    def __call__(self, q: np.ndarray, q_next: np.ndarray) -> str:
        """Why the step from ``q`` to ``q_next`` (each ``(D,)``) must not be taken, or ``""``.

        The step is refused when, at a point along it, the robot would be nearer the person than ``stop_m`` and
        nearer than it is now.
        """
        bodies, body_radii = self._bodies, self._body_radii
        if not bodies or self.config.stop_m <= 0:
            return ""
        q, q_next = np.asarray(q, dtype=np.float64), np.asarray(q_next, dtype=np.float64)
        n = min(MAX_POINTS, max(1, math.ceil(float(np.max(np.abs(q_next - q))) / MAX_STEP_RAD)))
        path = q + (q_next - q) * np.linspace(0.0, 1.0, n + 1)[:, None]  # (n + 1, D)
        centres = sphere_centres(self.robot, path)  # (n + 1, S, 3)
        ends = np.stack([e for _, e in bodies])  # (P, C, 2, 3)
        gaps = sphere_capsule_clearance(centres[:, None], self.radii, ends[None], body_radii)  # (n + 1, P)
        nearest = gaps.min(axis=1)
        now, then = float(nearest[0]), float(nearest[1:].min())
        self.clearance_ = now
        if then < self.config.stop_m and then < now:
            self.holds_ += 1
            return SEPARATION_REASON.format(clearance=max(now, 0.0), stop_m=self.config.stop_m)
        return ""


def separation_guard(config: ExecutorConfig, robot: Any, scene: Any) -> SeparationGuard | None:
    """The executor's guard: in real time with ``separation.stop_m`` > 0, else None (lock-step: a measurement)."""
    if config.mode != "realtime" or config.separation.stop_m <= 0:
        return None
    return SeparationGuard(config.separation, robot, scene)
