"""Foxglove's small value messages built from numbers: times, vectors, colours, poses and spheres.

One place for what every drawing needs (:mod:`shared.foxglove.scene` and :mod:`shared.foxglove.keypoints`),
so that a point, a colour or a lifetime is converted the same way everywhere.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from foxglove.messages import Color, Duration, Point3, Pose, Quaternion, SpherePrimitive, Timestamp, Vector3

__all__ = ["timestamp", "duration", "vector3", "point3", "color", "pose_at", "spheres"]

_NS = 1_000_000_000


def timestamp(seconds: float) -> Timestamp:
    """The ``Timestamp`` of a non-negative time in seconds (rounded to the nanosecond; a negative one is 0)."""
    ns = max(0, int(round(seconds * 1e9)))
    return Timestamp(sec=ns // _NS, nsec=ns % _NS)


def duration(seconds: float) -> Duration:
    """The ``Duration`` of a non-negative span in seconds (rounded to the nanosecond; a negative one is 0)."""
    ns = max(0, int(round(seconds * 1e9)))
    return Duration(sec=ns // _NS, nsec=ns % _NS)


def vector3(p: np.ndarray | list[float]) -> Vector3:
    """``Vector3`` of the first three values of ``p``."""
    return Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def point3(p: np.ndarray | list[float]) -> Point3:
    """``Point3`` of the first three values of ``p``."""
    return Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def color(rgba: tuple[float, float, float, float] | np.ndarray) -> Color:
    """``Color`` of ``(r, g, b, a)`` in [0, 1]."""
    return Color(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def pose_at(p: np.ndarray | list[float], q: Quaternion | None = None) -> Pose:
    """The ``Pose`` at position ``p`` with orientation ``q`` (default: the identity)."""
    return Pose(position=vector3(p), orientation=q or Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def spheres(centers: np.ndarray, radii: float | Iterable[float], rgba: tuple[float, float, float, float]
            ) -> list[SpherePrimitive]:
    """One ``SpherePrimitive`` per centre, all of colour ``rgba``.

    Args:
        centers: ``(M, 3)`` sphere centres (m).
        radii: One radius for all (m), or ``M`` of them.
        rgba: Their colour, ``(r, g, b, a)`` in [0, 1].
    """
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radii, dtype=np.float64).reshape(-1), (len(centers),))
    fill = color(rgba)
    return [SpherePrimitive(pose=pose_at(c), size=vector3([2 * ri] * 3), color=fill)
            for c, ri in zip(centers, r, strict=True)]
