"""The clearance between the robot and a human's body: the robot's collision spheres against the body's capsules.

The experiments measure with it how close an executed trajectory came to the human who was really there
(``services.experiments.measures``); the executor's separation guard keeps the robot from closing in on the
person it sees (``services.executor.separation``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from shared.human import HumanModel

__all__ = ["body_clearance", "sphere_centres", "sphere_capsule_clearance", "segment_distance"]


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points to segments, broadcast: ``p (..., 3)``, ``a, b (..., 3)`` -> ``(...)``."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def sphere_centres(robot: Any, q: np.ndarray) -> np.ndarray:
    """``(N, S, 3)`` float64 centres of the robot's collision spheres at configurations ``q`` ``(N, D)``."""
    qt = torch.as_tensor(np.asarray(q, dtype=np.float64), dtype=robot.lower.dtype, device=robot.lower.device)
    with torch.no_grad():
        return robot.sphere_centers(qt).double().cpu().numpy()


def sphere_capsule_clearance(centres: np.ndarray, radii: np.ndarray, ends: np.ndarray,
                             body_radii: np.ndarray) -> np.ndarray:
    """The smallest surface-to-surface distance between spheres and capsules, broadcast over leading axes.

    Args:
        centres: ``(..., S, 3)`` sphere centres.
        radii: ``(S,)`` sphere radii.
        ends: ``(..., C, 2, 3)`` capsule end points (leading axes broadcast against ``centres``').
        body_radii: ``(C,)`` capsule radii.

    Returns:
        ``(...)`` the smallest distance (m) over every sphere and capsule; negative where they overlap.
    """
    c = np.asarray(centres, dtype=np.float64)[..., :, None, :]  # (..., S, 1, 3)
    e = np.asarray(ends, dtype=np.float64)[..., None, :, :, :]  # (..., 1, C, 2, 3)
    d = segment_distance(c, e[..., 0, :], e[..., 1, :])  # (..., S, C)
    gap = d - np.asarray(radii, dtype=np.float64)[:, None] - np.asarray(body_radii, dtype=np.float64)[None, :]
    return gap.min(axis=(-2, -1))


def body_clearance(robot: Any, q: np.ndarray, postures: np.ndarray, human: HumanModel | None = None) -> np.ndarray:
    """Clearance between the robot and the human's body at each instant.

    Args:
        robot: Robot model with ``sphere_centers`` and ``sphere_radii``.
        q: ``(N, D)`` robot configurations.
        postures: ``(N, 12)`` scene-frame human postures at the same instants.
        human: The human model (default: a new :class:`HumanModel`).

    Returns:
        ``(N,)`` the smallest surface-to-surface distance (m) between any robot sphere and any body
        capsule; negative where they overlap.
    """
    human = human or HumanModel()
    centres = sphere_centres(robot, q)  # (N, S, 3)
    ends, r_body = human.capsules(np.asarray(postures, dtype=np.float64))  # (N, C, 2, 3), (C,)
    return sphere_capsule_clearance(centres, robot.sphere_radii.double().cpu().numpy(), ends, np.asarray(r_body))
