"""What :class:`~services.planner.core.Planner` needs from its robot, its cost and its goals.

``Planner(scene, config, robot=..., cost=..., goals=...)`` accepts any objects with these members
(structural typing, :class:`typing.Protocol`): the PR2 (:class:`shared.robot.PR2`), its
:class:`~services.planner.costs.StateCost` and :class:`~services.planner.goals.IKGoals` /
:class:`~services.planner.core.GoalSet` satisfy them, and so do the toy robot and cost of the tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import torch

__all__ = ["PlannerRobot", "PlannerCost", "PlannerGoals"]


class PlannerRobot(Protocol):
    """A robot model: its D planned joints and their limits.

    Attributes:
        joint_names: The D joints, in the order of a configuration's entries.
        lower, upper: ``(D,)`` position limits.
        velocity_limits: ``(D,)`` |velocity| limits (they time the trajectories and scale STOMP's noise).
    """

    joint_names: Sequence[str]
    lower: torch.Tensor
    upper: torch.Tensor
    velocity_limits: torch.Tensor


class PlannerCost(Protocol):
    """A state cost: per-waypoint (obstacle, human) terms of configurations, given the predicted occupancy."""

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        """``q`` ``(K, R, T, D)`` -> ``(K, R, T, 2)`` weighted (obstacle, human) terms."""
        ...

    def set_occupancy(self, occupancy: Any, origin: Any, resolution: float) -> None:
        """Set the predicted occupancy.

        Args:
            occupancy: ``(nx, ny, nz)`` probabilities in [0, 1]; None clears it.
            origin: ``(3,)`` lower corner of voxel (0, 0, 0) (m).
            resolution: Voxel edge (m).
        """
        ...


class PlannerGoals(Protocol):
    """The K goals planned for.

    Attributes:
        names: K goal names.
        q: ``(K, D)`` goal configurations (within the limits; arbitrary where invalid).
        valid: ``(K,)`` bool, goals that can be planned for.
        reasons: K strings, why a goal is invalid ("" when valid).
    """

    names: list[str]
    q: torch.Tensor
    valid: torch.Tensor
    reasons: list[str]
