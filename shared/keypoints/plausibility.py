"""Whether keypoints can be a person in the motion library's frame: metres, and z up (pure numpy).

The live tracker (:mod:`services.tracker.checks`, per frame), its file player and the keypoint library's fit
(:func:`shared.keypoints.library.fit_keypoint_library`, per demonstration) hold keypoints to the same two rules, so a
recording in millimetres or in a camera's frame is refused where it enters, in words that say what to change.
"""

from __future__ import annotations

import numpy as np

from shared.protocol.limits import MAX_KEYPOINT_M

from .fit import POINT_NAMES

__all__ = ["MAX_TILT_DEG", "MIN_TORSO_M", "torso_tilt_deg", "units_problem", "MAX_KEYPOINT_M"]

MAX_TILT_DEG = 60.0
"""The most the torso (pelvis to the shoulders' midpoint) may lean from the vertical: twice the most of any motion
of the paper's library or the synthetic one (30.4 and 30.8 deg)."""

MIN_TORSO_M = 0.2
"""The shortest torso whose lean is judged: half the model's (0.43 m, pelvis to the shoulders' midpoint)."""

_PELVIS, _R_SHOULDER, _L_SHOULDER = (POINT_NAMES.index(p) for p in ("pelvis", "r_shoulder", "l_shoulder"))


def torso_tilt_deg(points: np.ndarray) -> np.ndarray | float:
    """Degrees between the vertical (+z) and the torso, pelvis to the shoulders' midpoint.

    Args:
        points: ``(..., J, 3)`` Foresight's points (:data:`POINT_NAMES` order).

    Returns:
        ``(...)`` the lean; NaN where a point is missing or the torso is shorter than :data:`MIN_TORSO_M` (a wild
        point, a pelvis half a metre off, not a frame lying on its side: the fit's residual refuses it).
    """
    p = np.asarray(points, dtype=np.float64)
    v = (p[..., _R_SHOULDER, :] + p[..., _L_SHOULDER, :]) / 2 - p[..., _PELVIS, :]
    norm = np.linalg.norm(v, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        tilt = np.degrees(np.arccos(np.clip(v[..., 2] / norm, -1.0, 1.0)))
    tilt = np.where(norm >= MIN_TORSO_M, tilt, np.nan)
    return float(tilt) if tilt.ndim == 0 else tilt


def units_problem(names: list[str], positions: np.ndarray) -> str:
    """Why a recording's ``positions (T, K, 3)`` of the points ``names`` are not in metres ('' when they may be).

    Most of its frames (more than half) hold a coordinate beyond :data:`MAX_KEYPOINT_M` of the origin (what the wire
    refuses of a live sensor): a recording in millimetres reads as kilometres in every frame. A few such frames are
    a sensor's glitches, refused one by one on receipt or by the fit, not a wrong unit.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, len(names), 3)
    far = np.where(np.isfinite(p), np.abs(p), 0.0)
    beyond = far.max(axis=(1, 2)) > MAX_KEYPOINT_M  # (T,)
    if not beyond.sum() * 2 > len(p):
        return ""
    k = int(np.unravel_index(int(np.argmax(far)), far.shape)[1])
    return (f"coordinates beyond {MAX_KEYPOINT_M:g} m of the origin in {int(beyond.sum())} of its {len(p)} frames "
            f"(up to {float(far.max()):.1f} m, '{names[k]}'): keypoints are in metres (millimetres? divide by 1000)")
