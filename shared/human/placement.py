"""The human model in a scene: recorder-frame postures placed in the scene, voxels, reach points.

A demonstration is recorded in the motion-capture frame; :func:`place_in_scene` moves it rigidly so
that its first pelvis pose lands where the scene puts the human (``scene.human``). :func:`voxelize`
marks the voxels of a grid that points fall in; :func:`reach_points` finds where each
demonstration's hand reaches, in the scene (docs/human-model.md).
"""

from __future__ import annotations

import math

import numpy as np

from .model import HumanError, HumanModel, check_features

__all__ = ["place_in_scene", "place_points", "StreamPlacement", "voxelize", "reach_points"]


def place_in_scene(features: np.ndarray, first_pose: np.ndarray, scene) -> np.ndarray:
    """Move recorder-frame postures into a scene, relative to a demonstration's first pelvis pose.

    The pelvis pose (x, y, z, yaw) of ``first_pose`` goes to ``scene.human`` (pelvis_xyz,
    pelvis_yaw); every posture's pelvis moves rigidly with it (rotation about z by
    ``scene yaw - first yaw``, then translation); the joint angles are unchanged. Yaw is not
    wrapped, so a continuous recording stays continuous.

    Args:
        features: ``(..., 12)`` recorder-frame postures.
        first_pose: ``(12,)`` (or at least its first 4 entries) the reference posture, usually the
            first sample of the demonstration.
        scene: A :class:`shared.scene.Scene` (or anything with ``human.pelvis_xyz``/``pelvis_yaw``).

    Returns:
        ``(..., 12)`` scene-frame postures.
    """
    f = check_features(features)
    ref = check_features(first_pose, "first_pose")
    if ref.ndim != 1:
        raise HumanError(f"first_pose: expected shape (12,), got {ref.shape}")
    out = f.copy()
    out[..., 0:3] = place_points(f[..., 0:3], ref, scene)
    out[..., 3] = f[..., 3] + float(scene.human.pelvis_yaw) - ref[3]
    return out


def place_points(points: np.ndarray, first_pose: np.ndarray, scene) -> np.ndarray:
    """Move recorder-frame points ``(..., 3)`` as :func:`place_in_scene` moves a demonstration's pelvis.

    The rigid motion (rotation about z by ``scene yaw - first yaw``, then translation) that takes ``first_pose``'s
    pelvis (x, y, z, yaw: its first 4 entries) to ``scene.human``: a body tracker's keypoints, moved with it, meet
    the body of the poses fitted to them.
    """
    dyaw = float(scene.human.pelvis_yaw) - float(first_pose[3])
    c, s = math.cos(dyaw), math.sin(dyaw)
    d = np.asarray(points, dtype=np.float64) - np.asarray(first_pose[0:3], dtype=np.float64)
    out = np.empty_like(d)
    out[..., 0] = c * d[..., 0] - s * d[..., 1] + scene.human.pelvis_xyz[0]
    out[..., 1] = s * d[..., 0] + c * d[..., 1] + scene.human.pelvis_xyz[1]
    out[..., 2] = d[..., 2] + scene.human.pelvis_xyz[2]
    return out


class StreamPlacement:
    """A stream of poses placed in a scene as the predictor places them: relative to their demonstration's first pose.

    A demonstration joined part-way (a receiver started late, a first pose lost) is placed from the first of its
    poses seen; demonstration ids restart with a run, so a pose of index 0 always starts a placement.

    Args:
        scene: A :class:`shared.scene.Scene` (its ``human``).
    """

    def __init__(self, scene) -> None:
        self.scene = scene
        self.first_: tuple[int, np.ndarray] | None = None  # (demonstration id, its first pose seen (12,))

    def place(self, demo_id: int, index: int, features: np.ndarray) -> np.ndarray:
        """``(12,)`` the scene-frame posture of the pose ``features (12,)``, the ``index``-th of ``demo_id``."""
        if index == 0 or self.first_ is None or self.first_[0] != demo_id:
            self.first_ = (int(demo_id), np.array(features, dtype=np.float64))
        return place_in_scene(features, self.first_[1], self.scene)


def voxelize(points: np.ndarray, grid) -> np.ndarray:
    """Mark the voxels that contain at least one point.

    Args:
        points: ``(N, 3)`` (or ``(..., 3)``) positions in the grid's frame; points outside the
            grid are ignored.
        grid: A :class:`shared.scene.Grid`.

    Returns:
        ``(nx, ny, nz)`` bool occupancy.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise HumanError(f"points: expected shape (..., 3), got {p.shape}")
    p = p.reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    dims = grid.dims
    out = np.zeros(dims, dtype=bool)
    if len(p) == 0:
        return out
    idx = np.floor((p - grid.min) / grid.resolution).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < np.asarray(dims)), axis=1)
    idx = idx[inside]
    out[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return out


def reach_points(model: HumanModel, demos: list[np.ndarray], scene) -> tuple[np.ndarray, np.ndarray]:
    """Where each demonstration's hand reaches, placed in a scene.

    A demonstration may end at its goal or return to rest (the paper's recordings do): the reach
    point is the sample whose hand position is farthest from the first sample's.

    Args:
        model: The human model.
        demos: Demonstrations, each ``(T, 12)`` recorder-frame features.
        scene: Scene to place each one in (relative to its first posture).

    Returns:
        ``(reach (N, 3), index (N,))``: scene-frame hand positions and their sample indices.
    """
    reach, index = [], []
    for f in demos:
        hand = model.hand_position(place_in_scene(f, f[0], scene))
        k = int(np.argmax(np.linalg.norm(hand - hand[0], axis=-1)))
        reach.append(hand[k])
        index.append(k)
    return np.array(reach).reshape(-1, 3), np.array(index, dtype=np.int64)
