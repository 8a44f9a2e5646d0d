"""Whether keypoints can be a person in the motion library's frame: metres, and z up (pure numpy).

The live tracker (:mod:`services.tracker.checks`, per frame), its file player and the keypoint library's fit
(:func:`shared.keypoints.library.fit_keypoint_library`, per demonstration) hold keypoints to the same two rules, so a
recording in millimetres or in a camera's frame is refused where it enters, in words that say what to change. The
player and the fit hold a recorded demonstration to :func:`recording_problem` (those two, and a frame with every
required point), in the same words.
"""

from __future__ import annotations

import numpy as np

from shared.protocol.limits import MAX_KEYPOINT_M

from .fit import POINT_NAMES, REQUIRED
from .layouts import Layout

__all__ = ["MAX_TILT_DEG", "MIN_TORSO_M", "torso_tilt_deg", "units_problem", "MAX_KEYPOINT_M", "far_frames",
           "recording_problem"]

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


def far_frames(positions: np.ndarray) -> np.ndarray:
    """``(T,)`` which frames of ``positions (T, K, 3)`` hold a coordinate beyond :data:`MAX_KEYPOINT_M` of the origin.

    What the wire refuses of a live sensor's frame; in a recording, a few such frames are a sensor's glitches (the
    keypoint library's fit leaves them out, as the tracker would), most of them a wrong unit (:func:`units_problem`).
    """
    p = np.asarray(positions, dtype=np.float64)
    far = np.where(np.isfinite(p), np.abs(p), 0.0)
    return far.reshape(len(p), -1).max(axis=1, initial=0.0) > MAX_KEYPOINT_M


def units_problem(names: list[str], positions: np.ndarray) -> str:
    """Why a recording's ``positions (T, K, 3)`` of the points ``names`` are not in metres ('' when they may be).

    Most of its frames (more than half) hold a coordinate beyond :data:`MAX_KEYPOINT_M` of the origin (what the wire
    refuses of a live sensor): a recording in millimetres reads as kilometres in every frame. A few such frames are
    a sensor's glitches, refused one by one on receipt or by the fit, not a wrong unit.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, len(names), 3)
    beyond = far_frames(p)  # (T,)
    if not beyond.sum() * 2 > len(p):
        return ""
    far = np.where(np.isfinite(p), np.abs(p), 0.0)
    k = int(np.unravel_index(int(np.argmax(far)), far.shape)[1])
    return (f"coordinates beyond {MAX_KEYPOINT_M:g} m of the origin in {int(beyond.sum())} of its {len(p)} frames "
            f"(up to {float(far.max()):.1f} m, '{names[k]}'): keypoints are in metres (millimetres? divide by 1000)")


def recording_problem(layout: Layout, names: list[str], positions: np.ndarray) -> str:
    """Why a recorded demonstration cannot be a person in the library's frame ('' when it can).

    Not in metres (:func:`units_problem`), lying on its side (the torso's lean in the median frame beyond
    :data:`MAX_TILT_DEG`: z is not its up), or no frame with every required point in ``layout``'s terms. The tracker
    would refuse every frame of such a recording (on receipt, as ``upright``, as ``missing``) and the fit would
    clamp it to its bounds: ``tracker --from`` refuses it before it plays, and ``library from-keypoints`` before
    it fits, in these words.

    Args:
        layout: The layout that names the points.
        names: ``K`` the recording's point names (the layout's; a name it does not know is the caller's to refuse).
        positions: ``(T, K, 3)`` (NaN where missing).
    """
    if problem := units_problem(names, positions):
        return problem
    model = layout.to_model(names, positions)
    tilt = torso_tilt_deg(model)
    if np.isfinite(tilt).any() and np.nanmedian(tilt) > MAX_TILT_DEG:
        return (f"the torso (pelvis to the shoulders' midpoint) leans {np.nanmedian(tilt):.0f} deg from the vertical "
                f"(z) in the median frame, more than {MAX_TILT_DEG:g}: is z the keypoints' up? They must be in the "
                "library's frame")
    given = np.isfinite(model[:, [POINT_NAMES.index(p) for p in REQUIRED]]).all(-1)  # (T, R)
    if not given.all(-1).any():
        never = [layout.describe(p) for p, seen in zip(REQUIRED, given.any(0), strict=True) if not seen]
        return (f"no frame with every required point ({', '.join(REQUIRED)}; never given: "
                f"{', '.join(never) or 'none'}; layout {layout.name})")
    return ""
