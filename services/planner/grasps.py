"""Grasp poses at a cup: the candidate gripper poses (world frame, ``r_gripper_tool_frame``) of a pre-grasp.

For a cup, the candidates are pre-grasp poses at ``standoff`` from the cup's surface, approaching
horizontally from the robot's shoulder side (several yaw offsets and downward pitches) and/or from the
top, in preference order; :mod:`services.planner.goals` turns them into goal configurations by IK.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shared.scene import Cup

__all__ = ["GraspConfig", "grasp_candidates"]


@dataclass
class GraspConfig:
    """How grasp poses at cups are generated and solved."""

    approach: str = "any"  # "side", "top" or "any" (side candidates first, then top)
    standoff: float = 0.05  # tool frame to the cup surface along the approach (m)
    height_fraction: float = 0.5  # side approach: height on the cup (0 = base, 1 = rim)
    yaw_offsets_deg: tuple[float, ...] = (0.0, -25.0, 25.0, -50.0, 50.0)  # about the shoulder -> cup bearing
    pitch_deg: tuple[float, ...] = (0.0, 30.0)  # side approach tilted downwards by these angles
    n_seeds: int = 12  # IK seeds per candidate (the first is the start configuration)
    seed: int = 0
    max_iterations: int = 60
    pos_tolerance: float = 2e-3  # m
    rot_tolerance: float = 2e-2  # rad
    min_clearance: float = 0.0  # every moving sphere at least this far from the static obstacles (m)
    max_reach: float = 1.1  # shoulder-pan axis to target beyond this (m): unreachable without trying IK

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad value."""
        checks = [("approach", self.approach in ("side", "top", "any")), ("standoff", self.standoff >= 0),
                  ("height_fraction", 0 <= self.height_fraction <= 1), ("n_seeds", self.n_seeds >= 1),
                  ("yaw_offsets_deg", len(self.yaw_offsets_deg) > 0), ("pitch_deg", len(self.pitch_deg) > 0),
                  ("max_iterations", self.max_iterations >= 1), ("max_reach", self.max_reach > 0)]
        for name, ok in checks:
            if not ok:
                raise ValueError(f"grasp.{name}: bad value {getattr(self, name)!r}")


def _frame(x: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """Rotation with x axis ``x`` and z axis as close to ``z_hint`` as possible."""
    x = x / np.linalg.norm(x)
    z = z_hint - np.dot(z_hint, x) * x
    z = z / np.linalg.norm(z)
    return np.stack([x, np.cross(z, x), z], axis=1)


def grasp_candidates(cup: Cup, shoulder: np.ndarray, config: GraspConfig) -> list[tuple[str, np.ndarray]]:
    """Candidate world poses of the gripper tool frame for a pre-grasp at ``cup``.

    Side: the tool's x axis (approach) points horizontally from the shoulder towards the cup axis,
    rotated by each yaw offset and tilted down by each pitch; fingers open horizontally (tool z up);
    the tool point sits ``standoff`` before the cup wall at ``height_fraction`` of its height.
    Top: x points down, the fingers open across the shoulder -> cup bearing (rotated by each yaw
    offset), the tool point ``standoff`` above the rim centre.

    Args:
        cup: The cup.
        shoulder: ``(3,)`` world position of the shoulder (sets the approach bearing).
        config: Grasp settings.

    Returns:
        ``[(label, (4, 4) pose), ...]`` in preference order.
    """
    out: list[tuple[str, np.ndarray]] = []
    up = np.array([0.0, 0.0, 1.0])
    d = cup.position[:2] - shoulder[:2]
    bearing = math.atan2(d[1], d[0])
    if config.approach in ("side", "any"):
        for pitch in config.pitch_deg:
            for yaw in config.yaw_offsets_deg:
                b, p = bearing + math.radians(yaw), math.radians(pitch)
                a = np.array([math.cos(b) * math.cos(p), math.sin(b) * math.cos(p), -math.sin(p)])
                axis_point = cup.position + up * cup.height * config.height_fraction
                ah = np.array([math.cos(b), math.sin(b), 0.0])
                t = np.eye(4)
                t[:3, :3] = _frame(a, up)
                t[:3, 3] = axis_point - ah * cup.radius - a * config.standoff
                out.append((f"side yaw {yaw:+.0f} pitch {pitch:.0f}", t))
    if config.approach in ("top", "any"):
        for yaw in config.yaw_offsets_deg:
            b = bearing + math.radians(yaw)
            t = np.eye(4)
            t[:3, :3] = _frame(-up, np.array([math.cos(b), math.sin(b), 0.0]))
            t[:3, 3] = cup.position + up * (cup.height + config.standoff)
            out.append((f"top yaw {yaw:+.0f}", t))
    return out
