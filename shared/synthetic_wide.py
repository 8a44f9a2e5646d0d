"""A synthetic library of another feature set: 16 joint features, no mapping to the human model.

A stand-in for a user's own motion capture, which rarely has the paper's 12 features (the paper
authors' later data set, for one, has 16 per sample): the synthetic reaches of
:mod:`shared.synthetic` plus four channels of the right forearm and wrist that the human model does
not have (:data:`WIDE_EXTRA_NAMES`). Each extra channel follows the reach: it moves with the hand's
progress from its first to its farthest position, by an amount that depends on where the hand goes
(azimuth and elevation in the first pelvis frame), plus a per-demonstration offset and Kinect-like
jitter. The feature names (:data:`WIDE_FEATURE_NAMES`) have no mapping, so recognition works on
this library and the occupancy commands refuse it (``shared.feature_sets``).

Written as CSV (``foresight library generate --feature-set wide16``) it has 17 columns per row.
"""

from __future__ import annotations

import math

import numpy as np

from shared.feature_sets import HERAKLES_NAMES
from shared.human import HumanModel
from shared.library import Demonstration, MotionLibrary

__all__ = ["WIDE_EXTRA_NAMES", "WIDE_FEATURE_NAMES", "generate_wide_library", "extra_channels"]

WIDE_EXTRA_NAMES: tuple[str, ...] = ("r_forearm_twist", "r_wrist_flex", "r_wrist_dev", "r_hand_roll")
"""The four channels added to the 12 (radians)."""

WIDE_FEATURE_NAMES: tuple[str, ...] = HERAKLES_NAMES + WIDE_EXTRA_NAMES
"""The 16 features of the wide library, in column order."""

JITTER = 0.006
"""Standard deviation of the extra channels' measurement jitter (rad)."""


def extra_channels(features: np.ndarray, rng: np.random.Generator, model: HumanModel) -> np.ndarray:
    """The four extra channels of one demonstration.

    Args:
        features: ``(T, 12)`` the demonstration's recorder-frame features (paper order).
        rng: Random generator (per-demonstration offsets and jitter).
        model: The human model (hand positions).

    Returns:
        ``(T, 4)`` forearm twist, wrist flexion, wrist deviation and hand roll, radians.
    """
    hand = model.hand_position(features)                                   # (T, 3)
    yaw0 = float(features[0, 3])
    c, s = math.cos(-yaw0), math.sin(-yaw0)
    d = hand - hand[0]
    local = np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]])
    dist = np.linalg.norm(local, axis=1)
    far = int(np.argmax(dist))
    progress = dist / max(float(dist[far]), 1e-6)                          # (T,) 0 at rest, 1 at the reach
    azimuth = math.atan2(local[far, 1], local[far, 0])
    elevation = math.atan2(local[far, 2], math.hypot(local[far, 0], local[far, 1]))
    gain = np.array([0.9 * math.cos(azimuth), 0.8 * elevation, 0.6 * math.sin(azimuth), 0.25])
    offset = np.array([0.3, -0.15, 0.0, 0.0]) + rng.normal(0.0, 0.05, 4)
    t = len(features)
    raw = rng.normal(size=(t + 4, 4))
    window = np.hanning(7)[1:-1]
    window /= np.sqrt(np.sum(window * window))
    jitter = sum(window[k] * raw[k:k + t] for k in range(5))
    return offset + progress[:, None] * gain + JITTER * jitter


def generate_wide_library(n_classes: int = 4, n_demos: int = 25, seed: int = 0, **kwargs) -> MotionLibrary:
    """Generate the 16-feature synthetic library.

    Args:
        n_classes: Number of classes M (goals of the layout).
        n_demos: Demonstrations per class.
        seed: Seed of every random draw (the 12 features are those of
            ``shared.synthetic.generate_library`` with the same seed).
        **kwargs: ``layout``, ``scene``, ``config`` of ``generate_library``.

    Returns:
        The library, ``feature_names`` :data:`WIDE_FEATURE_NAMES` (no mapping).
    """
    from shared.synthetic import generate_library

    base = generate_library(n_classes, n_demos, seed, **kwargs)
    rng = np.random.default_rng([seed, len(WIDE_FEATURE_NAMES)])
    model = HumanModel()
    demos = []
    for d in base.demos:
        f = np.ascontiguousarray(np.hstack([d.features, extra_channels(d.features, rng, model)]))
        f.setflags(write=False)
        demos.append(Demonstration(d.label, d.class_name, d.index, f, d.source))
    return MotionLibrary(list(base.class_names), demos, [], base.source.replace("synthetic:", "synthetic-wide16:", 1),
                         WIDE_FEATURE_NAMES)
