"""A recorded demonstration as a live person's reach: the poses the tracker would publish for it (no Zenoh, no files).

The recognition measured on a library's recorded features (``foresight eval recognition``) reads each reach from
its first sample, at rest, without a sensor. A live person's reach comes through the tracker: body keypoints with a
sensor's noise, the human model fitted to them (gaps bridged), One-Euro smoothing, and the reach rule that starts
the reach (its first pose ``pre_s`` before the wrist left rest, index 0 there) and ends it. :func:`sense_reach`
plays a demonstration so: the human model's joint positions of every sample (what ``foresight library
to-keypoints`` writes, here in memory), with seeded Gaussian noise per axis, frame by frame at the library's rate
into a real :class:`~services.tracker.core.TrackerCore`, and keeps the first reach's poses.

The demonstration is padded with its first posture before and its last after, as ``foresight tracker --from``
plays a recording (:class:`~services.tracker.config.PlaybackConfig` ``lead_s`` and ``hold_s``, 1.5 s each): the
person stands at rest while the tracker learns where the hand rests (``rest_s``, 1 s; no reach starts before), and
the hand stays at the goal long enough for the rule to end the reach (``end_s``, 1 s, of a still hand). Unlike the
playback of a file, every padded frame has noise of its own, as a sensor watching a still person gives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shared.feature_sets import LIVE_MAPPING, require_mapping
from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES
from shared.protocol import DemoMarker, HumanPose

from .config import PlaybackConfig
from .core import TrackerConfig, TrackerCore
from .demos import reach_messages

__all__ = ["SensedReach", "sense_reach"]


@dataclass(frozen=True)
class SensedReach:
    """The first reach the tracker published for a demonstration.

    Attributes:
        features: ``(P, 12)`` its poses' features, in order; pose ``k`` has index ``k`` (the predictor's time).
        start: The recording's sample of its first pose (negative: a pose of the rest before the first sample).
        end: The recording's sample of its last pose (``>= T``: of the rest held after the last sample).
    """

    features: np.ndarray
    start: int
    end: int


def sense_reach(features: np.ndarray, feature_names: tuple[str, ...] | list[str], noise_m: float = 0.0,
                seed: int | tuple[int, ...] = 0, config: TrackerConfig | None = None,
                playback: PlaybackConfig | None = None, model: HumanModel | None = None) -> SensedReach | None:
    """The first reach the tracker publishes for a demonstration played as a person's body keypoints.

    Args:
        features: ``(T, 12)`` the demonstration's posture features at ``config.pose_rate_hz``, from rest.
        feature_names: Their names (the paper's 12: what the human model places and the tracker fits).
        noise_m: Standard deviation of the keypoints' Gaussian noise per axis, m (a depth camera's: 0.01-0.03).
        seed: Seed of the noise (``numpy.random.default_rng``): the same poses for the same seed.
        config: The tracker's options (default ``TrackerConfig()``; layout ``foresight``: the keypoints are the
            human model's points by their own names).
        playback: ``lead_s`` and ``hold_s``: how long the first and last postures are held (default
            ``PlaybackConfig()``, as ``foresight tracker --from``).
        model: The human model placing the keypoints (default ``HumanModel()``; the tracker fits its own default).

    Returns:
        The reach's poses and where it started and ended, or None where the tracker started no reach.

    Raises:
        ValueError: Features not the paper's 12, ``noise_m`` not finite and >= 0, or a layout other than
            ``foresight``.
    """
    mapping = require_mapping(feature_names, "the tracker's poses (the human model's keypoints)", exact=LIVE_MAPPING)
    if not (math.isfinite(noise_m) and noise_m >= 0):
        raise ValueError(f"noise_m: must be a finite number >= 0, got {noise_m}")
    config = config or TrackerConfig()
    if config.layout != "foresight":
        raise ValueError(f"config.layout: the keypoints bear the human model's names (foresight), not {config.layout}")
    playback = playback or PlaybackConfig()
    rate = config.pose_rate_hz
    lead, hold = round(playback.lead_s * rate), round(playback.hold_s * rate)
    f = np.asarray(features, dtype=np.float64)
    padded = np.concatenate([np.repeat(f[:1], lead, axis=0), f, np.repeat(f[-1:], hold, axis=0)])
    points = (model or HumanModel()).joint_positions(mapping.to_human(padded))  # (lead + T + hold, J, 3)
    if noise_m > 0:
        points = points + np.random.default_rng(seed).normal(0.0, noise_m, points.shape)
    core, names, messages = TrackerCore(config), list(POINT_NAMES), []
    for k, frame in enumerate(points):
        messages += core.on_frame(k / rate, names, frame, k).messages
    messages += core.finish(recording_ended=True).messages
    reach = reach_messages(messages, set())  # the person seen at rest left out
    first = next((m.demo_id for m in reach if isinstance(m, DemoMarker) and m.event == "start"), None)
    poses = [m for m in reach if isinstance(m, HumanPose) and m.demo_id == first]
    if not poses:
        return None
    sample = [round(p.stamp * rate) - lead for p in (poses[0], poses[-1])]
    return SensedReach(np.array([p.features for p in poses], dtype=np.float64), sample[0], sample[1])
