"""Leave-one-out recognition of a reach as a live person's comes through the tracker (``--through-tracker``).

:func:`~services.predictor.recognition.leave_one_out` classifies each held-out demonstration's recorded features,
from its first sample at rest. Here each held-out demonstration is played through the tracker first
(:func:`services.tracker.sensed.sense_reach`: keypoints with a sensor's noise, the fit, the smoothing, the reach
rule), and the poses of the first reach it publishes are classified as the live predictor reads them: pose ``k`` at
time index ``k``, indices past the training motions' last read as it (the model's ``last_index``). The prefixes are
10%, ..., 100% of those poses. The mixtures are fitted as in ``leave_one_out`` (the held-out demonstration's class
refitted without it), on the recorded features from their first sample (``time_from="recording"``) or cut where the
tracker's reach rule starts each (``"tracker"``: the cut of ``foresight train --time-from tracker``).

A demonstration for which the tracker starts no reach is counted as not recognised (every class equally likely:
log-likelihood 0), and counted in :attr:`TrackedRecognition.no_reach`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from joblib import Parallel, delayed

from shared.feature_sets import LIVE_MAPPING, MappingError, require_mapping
from shared.library import MotionLibrary
from shared.progress import progress as progress_bar
from shared.runtime import UserError

from .features import FeatureEncoder
from .fit_cache import class_fit
from .gmm import GMMConfig, MixtureBank
from .model import TIME_FROM
from .recognition import FRACTIONS, RecognitionResult, prefix_scores
from .train import DEFAULT_FEATURES

__all__ = ["TrackedRecognition", "sense_library", "leave_one_out_tracked", "tracker_label"]


@dataclass
class TrackedRecognition:
    """Recognition through the tracker: the rates, and what the tracker made of the demonstrations.

    Attributes:
        result: The recognition (``log_likelihood`` 0 and ``correct`` False for a demonstration without a reach).
        no_reach: ``(K,)`` indices of the demonstrations for which the tracker started no reach.
        poses: ``(N,)`` poses of each demonstration's first reach (0: none).
        starts: The recording's sample of each reach's first pose (None: no reach; negative: in the rest before).
    """

    result: RecognitionResult
    no_reach: np.ndarray
    poses: np.ndarray
    starts: list[int | None]

    def line(self) -> str:
        """One line: demonstrations without a reach, and the reaches' poses and starts."""
        n, k = len(self.poses), len(self.no_reach)
        got = self.poses[self.poses > 0]
        starts = [s for s in self.starts if s is not None]
        where = (f"; the reaches' poses median {np.median(got):g} (range {got.min()}-{got.max()}), first pose at "
                 f"the recording's sample median {np.median(starts):g} (range {min(starts)}-{max(starts)})"
                 if len(got) else "")
        return (f"through the tracker: {k} of {n} demonstrations started no reach (counted as not recognised)"
                + where)

    def summary(self, noise_m: float, time_from: str, seed: int) -> dict:
        """The JSON object of ``--through-tracker``: the options, the counts, the reaches' poses and starts."""
        return {"keypoint_noise_m": noise_m, "time_from": time_from, "seed": seed, "n_demos": len(self.poses),
                "no_reach": len(self.no_reach), "no_reach_demos": self.no_reach.tolist(),
                "poses": self.poses.tolist(), "starts": self.starts, "label": tracker_label(noise_m, time_from)}


def tracker_label(noise_m: float, time_from: str) -> str:
    """The variant's words: ``through the tracker, keypoint noise X cm, time from ...``."""
    return f"through the tracker, keypoint noise {noise_m * 100:g} cm, time from {time_from}"


def _sense(features: np.ndarray, names: tuple[str, ...], noise_m: float, seed: tuple[int, int]) -> tuple | None:
    from services.tracker.sensed import sense_reach

    r = sense_reach(features, names, noise_m, seed)
    return None if r is None else (r.features, r.start)


def sense_library(library: MotionLibrary, noise_m: float, seed: int = 0, n_jobs: int = 1,
                  progress: bool = True) -> list[tuple[np.ndarray, int] | None]:
    """Every demonstration's first reach through the tracker: ``((P, 12) poses, start sample)``, or None.

    Demonstration ``i``'s keypoint noise is seeded with ``(seed, i)``: the same poses on every run, whatever
    ``n_jobs``. One to two seconds per demonstration (the keypoint fit of every frame).
    """
    try:
        require_mapping(library.feature_names, "--through-tracker (the tracker's fit of body keypoints)",
                        f"library {library.source}", exact=LIVE_MAPPING)
    except MappingError as exc:
        raise UserError(str(exc)) from None
    jobs = (delayed(_sense)(d.features, library.feature_names, noise_m, (seed, i)) for i, d in enumerate(library.demos))
    it = Parallel(n_jobs=n_jobs, return_as="generator")(jobs)
    return list(progress_bar(it, total=len(library.demos), desc="through the tracker", unit="demo", enabled=progress))


def leave_one_out_tracked(library: MotionLibrary, cfg: GMMConfig, sensed: list[tuple[np.ndarray, int] | None],
                          features: str = DEFAULT_FEATURES, time_from: str = "recording",
                          fractions: tuple[float, ...] = FRACTIONS, n_jobs: int = 1, progress: bool = True,
                          name: str = "") -> TrackedRecognition:
    """Leave one out, each held-out demonstration classified from the tracker's poses.

    Args:
        library: Motion library of the paper's 12 features (at least 2 demonstrations per class).
        cfg: Mixture options.
        sensed: :func:`sense_library`'s reaches, one per demonstration.
        features: Feature variant.
        time_from: Where the training demonstrations' time starts (:data:`~services.predictor.model.TIME_FROM`).
        fractions: Fractions of the reach's poses to classify at.
        n_jobs: Parallel refits (joblib processes).
        progress: Show a progress bar.
        name: Label of the result (default: the features, components and :func:`tracker_label` without noise).

    Returns:
        The rates and the demonstrations without a reach.
    """
    if time_from not in TIME_FROM:
        raise UserError(f"--time-from {time_from!r} is not one of {', '.join(TIME_FROM)}")
    if min(library.counts()) < 2:
        raise UserError(f"library {library.source}: leave-one-out needs >= 2 demonstrations per class, "
                        f"got {library.counts()}")
    if len(sensed) != len(library.demos):
        raise ValueError(f"sensed: {len(sensed)} reaches for {len(library.demos)} demonstrations")
    demos = list(library.demos)
    if time_from == "tracker":  # the trainer's cut (services.predictor.train, --time-from tracker)
        from services.tracker.reach import from_tracker_start
        demos = from_tracker_start(demos)
    encoder = FeatureEncoder(features, feature_names=library.feature_names, source=f"library {library.source}")
    feats = [encoder.batch(d.features) for d in demos]
    labels = np.array([d.label for d in demos])
    lengths = np.array([d.n_samples for d in demos])
    fit = partial(class_fit, gmm=cfg)
    full = MixtureBank.from_sklearn(Parallel(n_jobs=n_jobs)(
        delayed(fit)(np.vstack([feats[j] for j in np.flatnonzero(labels == m)])) for m in range(library.n_classes)))
    have = [i for i, s in enumerate(sensed) if s is not None]
    # the held-out model's last_index, as train_model writes it: its longest demonstration's samples, less one
    def reading(i: int) -> np.ndarray:  # the live predictor's reading: pose k at time k (at most last_index)
        return FeatureEncoder(features, feature_names=library.feature_names,
                              last_index=int(np.delete(lengths, i).max()) - 1).batch(sensed[i][0])  # type: ignore[index]

    jobs = (delayed(prefix_scores)(i, reading(i), feats, labels, full, fit, fractions) for i in have)
    it = Parallel(n_jobs=n_jobs, return_as="generator")(jobs)
    cum = np.zeros((len(demos), len(fractions), library.n_classes))
    for i, c in zip(have, progress_bar(it, total=len(have), desc=f"leave-one-out ({features}, tracker's poses)",
                                       unit="demo", enabled=progress), strict=True):
        cum[i] = c
    correct = np.argmax(cum, axis=2) == labels[:, None]
    missing = np.array([i for i, s in enumerate(sensed) if s is None], dtype=int)
    correct[missing] = False  # no reach: nothing recognised
    label = name or (f"Foresight, {features} features, {cfg.n_components or 'BIC'} Gaussians per class, "
                     f"{tracker_label(0.0, time_from)}")
    result = RecognitionResult(label, list(fractions), correct.mean(axis=0).tolist(), correct, labels, cum)
    poses = np.array([0 if s is None else len(s[0]) for s in sensed])
    starts = [None if s is None else s[1] for s in sensed]
    return TrackedRecognition(result, missing, poses, starts)
