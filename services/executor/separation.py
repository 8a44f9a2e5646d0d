"""The separation guard: near the person it sees, the robot makes no move that brings it closer (real time).

Beyond the paper. The planner keeps the robot out of where the person is *predicted* to be; where the prediction is
wrong (a motion unlike every class, a person who leans in instead of reaching), nothing kept the robot from closing
in on the person it could see. The guard is the last check before each simulation step, in the spirit of ISO/TS
15066's speed and separation monitoring: once the clearance between the robot's collision spheres and the person's
body (the human model's capsules, posed by the latest ``HumanPose`` and placed as the predictor places it) is under
``stop_m``, a step that would shrink it is not taken; the robot holds (``RobotState.reason`` says so) and moves again
as soon as its next step keeps or widens the clearance: the person stepped back, or the plan leads away from them.

Real time only. A lock-step run is a measurement of the planners (the experiments and ``foresight demo`` compare
their contact with the human), which a guard stopping the robot would hide; its human is a recording.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from shared.clearance import body_clearance
from shared.human import HumanModel, StreamPlacement

from .config import SEPARATION_REASON, ExecutorConfig, SeparationConfig

__all__ = ["SeparationGuard", "separation_guard"]


class SeparationGuard:
    """Decides, before each simulation step, whether the step would close in on the person.

    Args:
        config: Its options.
        robot: The robot model (``sphere_centers``, ``sphere_radii``; the executor's joint order).
        scene: The scene the person is placed in (``scene.human``).
        human: The human model (default: a new :class:`HumanModel`).

    Attributes:
        posture_: ``(12,)`` the person's latest scene-frame posture (None before any pose).
        clearance_: The robot's clearance to it at the last check (m; inf before any).
        holds_: Steps the guard held.
    """

    def __init__(self, config: SeparationConfig, robot: Any, scene: Any, human: HumanModel | None = None) -> None:
        self.config = config
        self.robot = robot
        self.human = human or HumanModel()
        self.placement = StreamPlacement(scene)
        self.posture_: np.ndarray | None = None
        self.clearance_ = math.inf
        self.holds_ = 0

    def note_pose(self, demo_id: int, index: int, features: np.ndarray) -> None:
        """The person's latest pose: ``features`` ``(12,)``, the ``index``-th of demonstration ``demo_id``."""
        self.posture_ = self.placement.place(demo_id, index, features)

    def __call__(self, q: np.ndarray, q_next: np.ndarray) -> str:
        """Why the step from ``q`` to ``q_next`` (each ``(D,)``) must not be taken, or ``""``.

        The step is refused when it ends nearer the person than ``stop_m`` and nearer than it starts.
        """
        if self.posture_ is None or self.config.stop_m <= 0:
            return ""
        now, then = body_clearance(self.robot, np.stack([q, q_next]), np.stack([self.posture_] * 2), self.human)
        self.clearance_ = float(now)
        if then < self.config.stop_m and then < now:
            self.holds_ += 1
            return SEPARATION_REASON.format(clearance=float(now), stop_m=self.config.stop_m)
        return ""


def separation_guard(config: ExecutorConfig, robot: Any, scene: Any) -> SeparationGuard | None:
    """The executor's guard: in real time with ``separation.stop_m`` > 0, else None (lock-step: a measurement)."""
    if config.mode != "realtime" or config.separation.stop_m <= 0:
        return None
    return SeparationGuard(config.separation, robot, scene)
