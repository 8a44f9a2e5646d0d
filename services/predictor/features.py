"""Feature vectors the class mixtures are fitted on: time plus the F posture features (and variants).

Every variant starts with the time (the sample index times ``time_scale``) followed by the
library's F posture features in its column order (the paper's 12, :data:`shared.library.FEATURE_NAMES`,
or any other feature set), so GMR conditioned on column 0 regresses columns 1..F back into a
posture. Variants:

- ``paper``: ``[t, features]`` exactly as recorded (the paper, IV.A); any feature set.
- ``relative``: the pelvis x, y, z and yaw are taken relative to the demonstration's first pelvis
  pose (rotated into its heading), so where the recorder stood does not matter.
- ``relative_velocity``: ``relative`` plus the per-sample change of the 5 arm features
  (backward differences, 0 at the first sample; online, over the samples since the last observed one),
  times ``velocity_scale``.
- ``hand``: ``paper`` plus the right hand's position (m) in the frame of the demonstration's first
  pelvis pose (``shared.human.HumanModel.hand_position``), a Euclidean feature of where the reach goes.

``relative``, ``relative_velocity`` and ``hand`` use the paper's columns (pelvis pose, arm joints,
the human model): they need the paper's 12 features (``shared.feature_sets.HERAKLES``).

The same encoder serves training (:meth:`FeatureEncoder.batch`) and the online query
(:meth:`FeatureEncoder.step`); both give identical vectors.

A model's encoder holds the last sample index its mixtures were fitted on (``last_index``) and encodes a later
index as that one: the mixtures know nothing of later times, and scoring a posture held past the end of the
training motions at its true index ranked the classes by how wide their last Gaussians are in time, not by the
posture (the paper's library, postures held after sample 99: 92 % of held-out demonstrations recognised at
index 99, 8 % at index 200). A live reach that pauses at its goal, or a sensor slower than the library, runs
past the end; a slower reach is still compared at the library's pace before it.
"""

from __future__ import annotations

import math

import numpy as np

from shared.feature_sets import HERAKLES, HERAKLES_NAMES, require_mapping

__all__ = ["VARIANTS", "FeatureEncoder", "N_POSTURE"]

VARIANTS = ("paper", "relative", "relative_velocity", "hand")
N_POSTURE = 12
"""Posture features of the paper's feature set (the default)."""
_ARM = slice(7, 12)


def _relative(f: np.ndarray, first: np.ndarray) -> np.ndarray:
    out = np.array(f, dtype=np.float64, copy=True)
    yaw0 = float(first[3])
    c, s = math.cos(-yaw0), math.sin(-yaw0)
    d = f[..., 0:3] - first[0:3]
    out[..., 0] = c * d[..., 0] - s * d[..., 1]
    out[..., 1] = s * d[..., 0] + c * d[..., 1]
    out[..., 2] = d[..., 2]
    # wrapped to (-pi, pi]: yaw0 = 3.1 and yaw = -3.1 are 0.083 rad apart, not -6.2
    out[..., 3] = math.pi - np.mod(math.pi - (f[..., 3] - yaw0), 2 * math.pi)
    return out


class FeatureEncoder:
    """Turns postures into the mixtures' feature vectors.

    Args:
        variant: One of :data:`VARIANTS`.
        time_scale: Time units per sample (1.0: the time feature is the sample index).
        velocity_scale: Multiplier of the velocity features (``relative_velocity``).
        feature_names: The F posture features (default: the paper's 12).
        source: The library or model the features come from (for the error message).
        last_index: The last sample index the mixtures were fitted on; later indices are encoded as it
            (None: no limit, as in training).

    Raises:
        ValueError: If ``variant`` is unknown.
        shared.feature_sets.MappingError: If a variant other than ``paper`` is asked of another
            feature set than the paper's.
    """

    def __init__(self, variant: str = "paper", time_scale: float = 1.0, velocity_scale: float = 10.0,
                 feature_names: tuple[str, ...] = HERAKLES_NAMES, source: str = "",
                 last_index: int | None = None) -> None:
        if variant not in VARIANTS:
            raise ValueError(f"feature variant {variant!r} is not one of {', '.join(VARIANTS)}")
        self.feature_names = tuple(feature_names)
        if variant != "paper":
            require_mapping(self.feature_names, f"feature variant {variant!r}", source, exact=HERAKLES)
        self.n_posture = len(self.feature_names)
        self.variant = variant
        self.time_scale = float(time_scale)
        self.velocity_scale = float(velocity_scale)
        if last_index is not None and last_index < 0:
            raise ValueError(f"last_index must be >= 0, got {last_index}")
        self.last_index = None if last_index is None else int(last_index)
        self._first: np.ndarray | None = None
        self._prev: np.ndarray | None = None
        self._prev_index: int | None = None
        self._human = None

    @property
    def dim(self) -> int:
        """Feature dimension D (time included)."""
        return 1 + self.n_posture + {"relative_velocity": 5, "hand": 3}.get(self.variant, 0)

    def batch(self, features: np.ndarray) -> np.ndarray:
        """Encode a whole demonstration.

        Args:
            features: ``(T, F)`` recorder-frame postures.

        Returns:
            ``(T, D)`` feature vectors.
        """
        f = np.asarray(features, dtype=np.float64)
        if f.ndim != 2 or f.shape[1] != self.n_posture:
            raise ValueError(f"features: expected shape (T, {self.n_posture}), got {f.shape}")
        t = self._time(np.arange(len(f)))[:, None]
        post = f if self.variant in ("paper", "hand") else _relative(f, f[0])
        cols = [t, post]
        if self.variant == "hand":
            cols.append(self._hand(f, f[0]))
        if self.variant == "relative_velocity":
            v = np.zeros((len(f), 5))
            v[1:] = np.diff(f[:, _ARM], axis=0)
            cols.append(v * self.velocity_scale)
        return np.hstack(cols)

    def reset(self) -> None:
        """Start a new demonstration (forget the first and previous posture)."""
        self._first = None
        self._prev = None
        self._prev_index = None

    def step(self, features: np.ndarray, index: int) -> np.ndarray:
        """Encode one posture of the demonstration being observed.

        Args:
            features: ``(F,)`` recorder-frame posture.
            index: Its sample index in the demonstration (0 for the first).

        Returns:
            ``(D,)`` feature vector.
        """
        f = np.asarray(features, dtype=np.float64)
        if self._first is None:
            self._first = f.copy()
        post = f if self.variant in ("paper", "hand") else _relative(f, self._first)
        parts = [self._time(np.array([index])), post]
        if self.variant == "hand":
            parts.append(self._hand(f, self._first))
        if self.variant == "relative_velocity":
            # the change per sample: a pose missing between two (refused, dropped) is not one sample's change
            gap = 1 if self._prev_index is None else max(1, index - self._prev_index)
            v = np.zeros(5) if self._prev is None else (f[_ARM] - self._prev[_ARM]) / gap
            parts.append(v * self.velocity_scale)
        self._prev = f.copy()
        self._prev_index = int(index)
        return np.concatenate(parts)

    def _time(self, index: np.ndarray) -> np.ndarray:
        """The time feature of sample indices (at most ``last_index``)."""
        i = index if self.last_index is None else np.minimum(index, self.last_index)
        return i.astype(np.float64) * self.time_scale

    def _hand(self, f: np.ndarray, first: np.ndarray) -> np.ndarray:
        if self._human is None:
            from shared.human import HumanModel

            self._human = HumanModel()
        return self._human.hand_position(_relative(f, first))

    def posture_columns(self) -> slice:
        """Columns of the feature vector that hold the F posture features (GMR outputs)."""
        return slice(1, 1 + self.n_posture)
