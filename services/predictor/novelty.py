"""Whether the observed motion is one the model knows: a novelty test on how well the last frames fit.

The class posterior says which known class explains the motion best, never whether any of them does: a
motion unlike every class still gets posteriors that sum to 1, often with one class near 1 (the least
unlikely). The predictor therefore also reports the motion's *familiarity* at frame t::

    s_t = max_m median_{t - W < u <= t} ln p(x_u | C_m)

how well the best-fitting class explains the last ``W`` frames (fewer at the start of a motion), in nats
per frame. The median over the window lets one glitch frame pass (a single implausible posture drops
``ln p`` by thousands) while a motion that leaves every class drops it for good; with one or two frames in the
window a median is no such guard, so a motion is judged from its :data:`MIN_FRAMES`-th frame on.

The threshold is learnt by ``foresight train`` from the training demonstrations themselves: each is held out
once (the folds of the temperature's cross-validation, :mod:`services.predictor.calibration`: its class's
mixture refitted without it, as a new person's known motion would be) and scored frame by frame as the
predictor scores a live motion. Its least ``s_t`` (from its third frame on) is how unfamiliar a known motion ever
looked. The threshold is the ``quantile`` of those minima (the one at ``floor(q (n - 1))`` of n, sorted): with
the default 0.05, about one held-out demonstration of a known class in twenty is called unfamiliar at some moment
of its motion, given enough of them; with 20 or fewer, none is (the least minimum: as quantile 0).

By default those demonstrations are scored as recorded: no sensor's noise is in the threshold, and a known reach seen
as body keypoints with 2 cm of noise, fitted back as the tracker does, falls below it at most frames. ``foresight
train --sensor-noise-m SIGMA`` scores them as the tracker would give them (:func:`through_sensor`: the human model's
keypoints with SIGMA of seeded noise per axis, fitted back and smoothed as the tracker does); the mixtures stay fitted
to the features as recorded, and the test records the noise it was calibrated for (docs/prediction.md, 'A noisy
sensor').
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from sklearn.mixture import GaussianMixture

from .calibration import fold_mixtures
from .gmm import MixtureBank

__all__ = ["DEFAULT_WINDOW", "DEFAULT_QUANTILE", "MIN_FRAMES", "NoveltyTest", "familiarity", "least_familiarity",
           "FamiliarityWindow", "heldout_minima", "learn_novelty", "threshold_at", "first_unfamiliar", "through_sensor"]

DEFAULT_WINDOW = 10
"""Frames the familiarity looks back over (a third of a second at 30 Hz)."""
DEFAULT_QUANTILE = 0.05
"""Share of held-out demonstrations of known classes called unfamiliar at some moment."""
MIN_FRAMES = 3
"""Frames a motion is observed before it can be called unfamiliar: the median of 3 passes one glitch frame (of 1
or 2 it is that frame, or half of it: a glitch at the first frame flagged the motion)."""
SCORE_FLOOR = -1e9
"""Familiarity is reported no lower than this (nats per frame): a finite number on the wire."""


@dataclass(frozen=True)
class NoveltyTest:
    """The learnt novelty test of a model.

    Attributes:
        threshold: A motion whose familiarity falls below it is unfamiliar (nats per frame).
        window: Frames W of the familiarity's median.
        quantile: The share of held-out training demonstrations the threshold lets fall below it.
        heldout: How many held-out demonstrations it was learnt from.
        sensor_noise_m: The keypoint noise per axis (m) the held-out demonstrations were scored under
            (:func:`through_sensor`); 0: their features as recorded.
    """

    threshold: float
    window: int = DEFAULT_WINDOW
    quantile: float = DEFAULT_QUANTILE
    heldout: int = 0
    sensor_noise_m: float = 0.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.threshold):
            raise ValueError(f"novelty threshold must be finite, got {self.threshold}")
        if not (isinstance(self.window, int | np.integer) and 1 <= self.window <= 10_000):
            raise ValueError(f"novelty window must be an integer in [1, 10000] frames, got {self.window!r}")
        if not (0.0 <= self.quantile < 1.0):
            raise ValueError(f"novelty quantile must be in [0, 1), got {self.quantile}")
        if not (np.isfinite(self.sensor_noise_m) and 0.0 <= self.sensor_noise_m < 1.0):
            raise ValueError(f"novelty sensor noise must be in [0, 1) m, got {self.sensor_noise_m}")

    def describe(self) -> str:
        """One line for ``foresight train``'s output and the predictor's start line, with the sensor it suits."""
        sensor = (f"scored as body keypoints with {self.sensor_noise_m * 100:g} cm of noise per axis, fitted back as "
                  "the tracker does" if self.sensor_noise_m else "scored as recorded: calibrated for no sensor's "
                  "noise (foresight train --sensor-noise-m)")
        return (f"novelty threshold {self.threshold:.2f} nats/frame over {self.window} frames (the "
                f"{self.quantile:g} quantile of {self.heldout} held-out demonstrations' least familiarity; {sensor})")


def familiarity(log_likelihood: np.ndarray, window: int = DEFAULT_WINDOW) -> np.ndarray:
    """The familiarity of every frame of one motion (what :class:`FamiliarityWindow` gives frame by frame).

    Args:
        log_likelihood: ``(T, M)`` per-frame ``ln p(x_t | C_m)``.
        window: Frames W of the median.

    Returns:
        ``(T,)`` ``s_t = max_m median(ln p(x_u | C_m), t - W < u <= t)``, floored at :data:`SCORE_FLOOR`.
    """
    ll = np.nan_to_num(np.asarray(log_likelihood, dtype=np.float64), nan=SCORE_FLOOR, neginf=SCORE_FLOOR)
    if ll.ndim != 2 or len(ll) == 0:
        raise ValueError(f"familiarity: expected (T >= 1, M) log-likelihoods, got shape {ll.shape}")
    padded = np.concatenate([np.full((window - 1, ll.shape[1]), np.nan), ll])   # the first windows are shorter
    windows = np.lib.stride_tricks.sliding_window_view(padded, window, axis=0)  # (T, M, W)
    return np.maximum(np.nanmedian(windows, axis=-1).max(axis=-1), SCORE_FLOOR)


def least_familiarity(scores: np.ndarray) -> float:
    """The least of a motion's ``(T,)`` familiarity scores from its :data:`MIN_FRAMES`-th frame on.

    (The last one for a shorter motion.) What :func:`heldout_minima` records and the threshold is compared with.
    """
    s = np.asarray(scores, dtype=np.float64)
    return float(s[min(MIN_FRAMES, len(s)) - 1:].min())


class FamiliarityWindow:
    """The familiarity of a live motion, one frame at a time (equals :func:`familiarity` of the frames so far).

    Args:
        window: Frames W of the median.
    """

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        self.window = int(window)
        self._frames: deque[np.ndarray] = deque(maxlen=self.window)

    def reset(self) -> None:
        """Forget the frames (a new motion)."""
        self._frames.clear()

    def push(self, log_likelihood: np.ndarray) -> float:
        """Add one frame's ``(M,)`` ``ln p(x_t | C_m)``; returns the familiarity ``s_t``."""
        ll = np.nan_to_num(np.asarray(log_likelihood, dtype=np.float64), nan=SCORE_FLOOR, neginf=SCORE_FLOOR)
        self._frames.append(ll)
        # the last window only (what familiarity() gives for the newest frame): 0.48 ms a pose through the batch
        # function's NaN-padded windows, a few microseconds so
        return float(max(np.median(np.stack(self._frames), axis=0).max(), SCORE_FLOOR))


def heldout_minima(feats: list[list[np.ndarray]], fit: Callable[[np.ndarray], GaussianMixture], folds: int,
                   window: int = DEFAULT_WINDOW, scored: list[list[np.ndarray]] | None = None) -> np.ndarray:
    """The least familiarity of every training demonstration, each scored with its fold held out.

    Args:
        feats: Per class, the encoded ``(T, D)`` feature vectors of each training demonstration.
        fit: Fits one class mixture to stacked ``(N, D)`` vectors (the trainer's, cached: the temperature's
            cross-validation fitted the same folds).
        folds: Folds (:func:`~services.predictor.calibration.fold_mixtures`, the temperature's).
        window: Frames W of the familiarity.
        scored: What each held-out demonstration is scored on, encoded as ``feats`` (e.g. through a sensor:
            :func:`through_sensor`); None: ``feats`` themselves. The mixtures are fitted to ``feats``.

    Returns:
        ``(N,)`` one minimum per held-out demonstration (empty when a class has fewer than 2).
    """
    if min(len(f) for f in feats) < 2 or folds < 2:
        return np.empty(0)
    seen = feats if scored is None else scored
    out = []
    for held, mixtures in fold_mixtures(feats, fit, folds):
        bank = MixtureBank.from_sklearn(mixtures)
        for m, js in enumerate(held):
            out.extend(least_familiarity(familiarity(bank.log_likelihood(seen[m][j]), window)) for j in js)
    return np.array(out)


def learn_novelty(feats: list[list[np.ndarray]], fit: Callable[[np.ndarray], GaussianMixture], folds: int,
                  window: int = DEFAULT_WINDOW, quantile: float = DEFAULT_QUANTILE,
                  scored: list[list[np.ndarray]] | None = None, sensor_noise_m: float = 0.0) -> NoveltyTest | None:
    """The novelty test of a training set, or None when no demonstration can be held out.

    Args:
        feats: Per class, the encoded ``(T, D)`` feature vectors of each training demonstration.
        fit: The trainer's (cached) class mixture fit.
        folds: Folds of the held-out scoring.
        window: Frames W of the familiarity.
        quantile: The threshold's quantile of the held-out minima (0: the least of them).
        scored: The held-out demonstrations as scored (:func:`heldout_minima`); None: ``feats``.
        sensor_noise_m: The sensor's noise ``scored`` went through, recorded in the test (0: none).
    """
    minima = heldout_minima(feats, fit, folds, window, scored)
    if minima.size == 0:
        return None
    return NoveltyTest(threshold_at(minima, quantile), window, quantile, int(minima.size), sensor_noise_m)


def through_sensor(features: list[list[np.ndarray]], noise_m: float, seed: int = 0) -> list[list[np.ndarray]]:
    """Demonstrations as the tracker gives a live person's: noisy body keypoints, fitted back and smoothed.

    Per demonstration: the human model's joint positions, Gaussian noise of ``noise_m`` per axis (one generator
    seeded with ``seed``, drawn demonstration by demonstration in the order given), the model fitted back frame by
    frame, each frame warm-started from the last one taken (:meth:`~shared.keypoints.fit.KeypointFit.fit_sequences`,
    the tracker's fit, refusing a frame over the tracker's ``max_residual_m``; a refused one is interpolated between
    the frames taken, as the tracker bridges it, however long the run of refusals: where the tracker would lose the
    person after ``max_gap_s``, this keeps the demonstration whole), then One-Euro smoothed with the tracker's
    defaults, a pose every ``1 / pose_rate_hz`` (:class:`services.tracker.core.TrackerConfig`). A person's
    ``[tracker]`` options are not known here: the calibration is for the defaults.

    Args:
        features: Per class, each demonstration's ``(T, 12)`` features as recorded (the paper's 12, the set the live
            pipeline streams).
        noise_m: Standard deviation of the noise per axis (m); 0: clean keypoints, still fitted back.
        seed: Seed of the noise.

    Returns:
        The same demonstrations' ``(T, 12)`` features as the tracker would publish them.
    """
    from services.tracker.core import TrackerConfig  # the tracker's fit, limits and smoothing: only when asked for
    from services.tracker.filters import smooth_sequence
    from shared.human import HumanModel
    from shared.keypoints.fit import KeypointFit

    cfg, model, rng = TrackerConfig(), HumanModel(), np.random.default_rng(seed)
    demos = [d for ds in features for d in ds]
    pts = [model.joint_positions(np.asarray(d, dtype=np.float64)) for d in demos]
    pts = [p + rng.normal(0.0, noise_m, p.shape) for p in pts] if noise_m > 0 else pts
    longest = max(len(p) for p in pts)
    batch = np.stack([np.concatenate([p, np.repeat(p[-1:], longest - len(p), 0)]) for p in pts])  # padding: unused
    res = KeypointFit().fit_sequences(batch, max_residual_m=cfg.max_residual_m)
    if res.refused is None:  # fit_sequences marks refusals whenever max_residual_m is given
        raise RuntimeError("through_sensor: KeypointFit.fit_sequences returned no refused frames for a max_residual_m")
    out: list[np.ndarray] = []
    for i, d in enumerate(demos):
        f, taken = res.features[i, :len(d)], ~res.refused[i, :len(d)]
        if taken.any() and not taken.all():
            t = np.arange(len(d))
            f = np.stack([np.interp(t, t[taken], f[taken, k]) for k in range(f.shape[1])], axis=-1)
        out.append(smooth_sequence(f, cfg.pose_rate_hz, cfg.min_cutoff_hz, cfg.beta))
    sizes = np.cumsum([0, *(len(ds) for ds in features)])
    return [out[a:b] for a, b in zip(sizes[:-1], sizes[1:], strict=True)]


def threshold_at(minima: np.ndarray, quantile: float) -> float:
    """The threshold of held-out ``(N,)`` least familiarities at ``quantile``.

    'lower': the threshold is one of the minima, so exactly the demonstrations below it are called unfamiliar.
    """
    return float(np.quantile(minima, quantile, method="lower"))


def first_unfamiliar(scores: np.ndarray, threshold: float) -> int | None:
    """The first frame of a motion's ``(T,)`` familiarity below ``threshold``; None when none is.

    Judged from the :data:`MIN_FRAMES`-th frame on, as :attr:`~services.predictor.core.PredictorCore.familiar` is.
    """
    below = np.flatnonzero(np.asarray(scores)[MIN_FRAMES - 1:] < threshold)
    return int(below[0]) + MIN_FRAMES - 1 if below.size else None
