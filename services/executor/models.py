"""The models the executor runs with: the robot (limits, start configuration, Foxglove view) and the human body.

:func:`load_models` builds the defaults (``shared.robot.PR2`` placed in the scene, ``shared.human``);
the Protocols say what the executor and its Foxglove view read of them, so tests and other robots
can stand in.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from shared.scene import Scene

from .core import ArmLimits, ExecutorConfig, ExecutorError

__all__ = ["RobotModel", "HumanBody", "PlaceInScene", "load_models", "start_configuration"]

log = logging.getLogger("foresight.executor")


class RobotModel(Protocol):
    """A robot model as the executor reads it (``shared.robot.PR2`` is one).

    Attributes:
        joint_names: The D joint names, in the order of every configuration.
        lower: ``(D,)`` lower joint limits (torch tensor or numpy array).
        upper: ``(D,)`` upper joint limits.
        velocity_limits: ``(D,)`` positive joint velocity limits (per second).
        q_start: ``(D,)`` the start configuration, or None.
    """

    joint_names: Sequence[str]
    lower: Any
    upper: Any
    velocity_limits: Any
    q_start: Any


class HumanBody(Protocol):
    """A human body model for the Foxglove view (``shared.human.HumanModel`` is one)."""

    def capsules(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(S, 2, 3)`` capsule end points and ``(S,)`` radii of a scene-frame posture ``(F,)``."""
        ...


class PlaceInScene(Protocol):
    """Moves recorder-frame postures into a scene (``shared.human.place_in_scene``)."""

    def __call__(self, features: np.ndarray, first_pose: np.ndarray, scene: Any) -> np.ndarray:
        """``(..., F)`` scene-frame postures of ``features``, relative to ``first_pose``."""
        ...


def load_models(scene: Scene, device: str = "cpu") -> tuple[RobotModel, HumanBody | None, PlaceInScene | None]:
    """The robot model placed in ``scene`` and the human model (``(robot, human, place_in_scene)``).

    The human model is optional for the executor (only the Foxglove view uses it): when it cannot
    be loaded, ``(robot, None, None)`` is returned with a warning.
    """
    import torch

    from shared.robot import PR2

    robot = PR2.from_scene(scene, device=device, dtype=torch.float32)
    try:
        from shared.human import HumanModel, place_in_scene

        return robot, HumanModel(), place_in_scene
    except Exception as exc:  # noqa: BLE001 - visualisation only
        log.warning("executor: human model unavailable (%s); the log will have no human body", exc)
        return robot, None, None


def start_configuration(limits: ArmLimits, config: ExecutorConfig, robot: RobotModel | None = None,
                        scene: Scene | None = None) -> np.ndarray:
    """The start configuration of the arm.

    ``config.start_q`` if given, else the robot model's ``q_start``, else the scene's torso lift with
    every other joint at 0 (clamped into the limits).

    Raises:
        ExecutorError: If ``config.start_q`` has the wrong length or leaves the joint limits.
    """
    if config.start_q:
        q = np.asarray(config.start_q, dtype=np.float64)
        if q.shape != (limits.dof,):
            raise ExecutorError(f"executor.start_q: expected {limits.dof} values {list(limits.joint_names)}, "
                                f"got {len(config.start_q)}")
        bad = [n for n, v, lo, hi in zip(limits.joint_names, q, limits.lower, limits.upper, strict=True)
               if not lo - 1e-9 <= v <= hi + 1e-9]
        if bad:
            raise ExecutorError(f"executor.start_q: outside the joint limits for {bad}")
        return q
    q_start = getattr(robot, "q_start", None)
    if q_start is not None:
        arr = q_start.detach().cpu().numpy() if hasattr(q_start, "detach") else q_start
        return limits.clamp(np.asarray(arr, dtype=np.float64))
    q = np.zeros(limits.dof)
    if scene is not None and "torso_lift_joint" in limits.joint_names:
        q[limits.joint_names.index("torso_lift_joint")] = scene.robot.torso_lift
    return limits.clamp(q)
