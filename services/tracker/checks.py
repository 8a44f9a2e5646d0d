"""A keypoint frame's plausibility, in words a sensor's user can act on (pure: no Zenoh).

* :func:`missing_points`: a required point the frame lacks, named with the sensor's own points it is made of;
* :func:`~shared.keypoints.plausibility.torso_tilt_deg`: how far the torso leans from the vertical (z) - keypoints
  left in a camera's frame (z forward) or a y-up frame lie on their side, which the fit would take for a person lying
  down;
* :func:`fit_without_outliers`: a fit refitted without the optional points far off it (a sensor that reports a
  point it did not detect at (0, 0, 0), as many do) while its residual is above the limit;
* :func:`furthest_point`: the observed point furthest from the fit, for the refusal's line.
"""

from __future__ import annotations

import numpy as np

from shared.keypoints.fit import POINT_NAMES, REQUIRED, FitResult, KeypointFit
from shared.keypoints.layouts import Layout
from shared.keypoints.plausibility import MAX_TILT_DEG, torso_tilt_deg

__all__ = ["MAX_TILT_DEG", "OUTLIER_FACTOR", "UPRIGHT_CONFIRM", "Upright", "missing_points", "torso_tilt_deg",
           "fit_without_outliers", "furthest_point"]

OUTLIER_FACTOR = 3.0
"""An optional point further than this many times ``max_residual_m`` from the fit is left out and the frame refitted
(a point where the sensor detected nothing; the default limit, 8 cm, makes it 24 cm)."""


UPRIGHT_CONFIRM = 15
"""Frames a track must stand upright (half a second at 30 Hz) before a lean beyond :data:`MAX_TILT_DEG` is taken
for a person bending over rather than keypoints whose up is not z."""


class Upright:
    """Whether a track's keypoints have z up: frames leaning too far are refused until it has stood upright.

    Frames leaning beyond :data:`MAX_TILT_DEG` are refused until the track has stood upright for
    :data:`UPRIGHT_CONFIRM` frames. Keypoints in a camera's frame (z forward) or a y-up one lean about 90 deg in
    every frame, from the first; a person bending over to pick something up leans as far, for a while, once tracked
    upright (judged frame by frame, such a bend ended the reach under way).

    Attributes:
        frames: Upright frames accepted in the current track.
    """

    def __init__(self) -> None:
        self.frames = 0

    def problem(self, tilt: float, new_track: bool) -> str:
        """Why a frame leaning ``tilt`` deg is refused ('' if it is not); ``new_track``: it would start a track."""
        upright = 0 if new_track else self.frames
        if not tilt > MAX_TILT_DEG or upright >= UPRIGHT_CONFIRM:
            return ""
        return (f"the torso (pelvis to the shoulders' midpoint) leans {tilt:.0f} deg from the vertical (z), more than "
                f"{MAX_TILT_DEG:g}, and the track has not stood upright for {UPRIGHT_CONFIRM} frames ({upright} so "
                "far): is z the keypoints' up? The sensor's extrinsic transform must bring them into the library's "
                "frame")

    def accepted(self, tilt: float, new_track: bool) -> None:
        """A frame leaning ``tilt`` deg was accepted (``new_track``: it started a track)."""
        if new_track:
            self.frames = 0
        if not tilt > MAX_TILT_DEG:
            self.frames += 1


def missing_points(layout: Layout, names: list[str], positions: np.ndarray, points: list[str]) -> str:
    """``points`` (Foresight's) in words: each with the sensor's points it is the mean of, and those not seen.

    E.g. ``pelvis (left_hip, right_hip: left_hip not seen)`` for COCO; ``r_wrist`` for Foresight's own names.
    """
    seen = {n for n, p in zip(names, np.asarray(positions), strict=True) if np.all(np.isfinite(p))}
    return ", ".join(layout.describe(point, seen) for point in points)


def fit_without_outliers(fit: KeypointFit, points: np.ndarray, observed: np.ndarray, prior: np.ndarray | None,
                         result: FitResult, max_residual_m: float) -> tuple[FitResult, list[str]]:
    """Refit without the optional points far off the fit (:data:`OUTLIER_FACTOR`) while its rms is above the limit.

    Each round leaves out the optional point furthest from the fit, if it is more than :data:`OUTLIER_FACTOR` x
    ``max_residual_m`` off; a required point, or none so far off, ends it.

    Args:
        fit: The fit that made ``result``.
        points: ``(J, 3)`` the frame's points (NaN where not observed).
        observed: ``(J,)`` which of them the fit used.
        prior: ``(1, 12)`` the previous frame's features, or None.
        result: The fit of the frame with every observed point (a batch of one).
        max_residual_m: The tracker's limit.

    Returns:
        The last fit and the points left out (none: ``result`` itself).
    """
    used, dropped = observed.copy(), []
    while float(result.rms_m[0]) > max_residual_m:
        r = np.where(used, result.residual_m[0], np.nan)
        if not np.isfinite(r).any():
            break
        j = int(np.nanargmax(r))
        if POINT_NAMES[j] in REQUIRED or not r[j] > OUTLIER_FACTOR * max_residual_m:
            break
        used[j] = False
        dropped.append(POINT_NAMES[j])
        result = fit.fit(np.nan_to_num(points)[None], used[None], prior)
    return result, dropped


def furthest_point(layout: Layout, result: FitResult) -> str:
    """The observed point furthest from the fit and its distance, e.g. ``r_wrist (right_wrist) 31 cm off``."""
    r = result.residual_m[0]
    if not np.isfinite(r).any():
        return "no point"
    j = int(np.nanargmax(r))
    return f"{layout.describe(POINT_NAMES[j])} {r[j] * 100:.0f} cm off"
