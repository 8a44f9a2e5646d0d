"""Body keypoints -> the paper's 12 posture features: the human model fitted to observed 3D points.

A batched, damped Gauss-Newton (Levenberg-Marquardt) least-squares fit of :class:`shared.human.HumanModel`'s
joint positions to the observed points, in numpy: for a batch of frames at once (a recording) or one frame
at a time warm-started from the previous one (live). Per frame it minimises

    sum_j w_j |p_j(f) - y_j|^2  +  sum_k (lambda_k (f_k - f0_k))^2

over the features ``f`` (12), where ``p_j`` is the model's position of point ``j``, ``y_j`` the observation
(``w_j`` 0 where missing), ``f0`` the prior (the previous frame's fit, or the first guess) and ``lambda`` a
small per-feature weight (:attr:`FitConfig.prior`) that resolves what the points leave open: the pelvis yaw
against the torso's own twist (the torso point is 4 cm in front of the pelvis), and a missing point's degrees
of freedom, which then stay where they were. Features are kept within :attr:`FitConfig.bounds` (the ranges of
the data the model was built from; ``shared.feature_sets.HERAKLES_RANGES`` by default), the pelvis yaw a whole
number of turns from its prior's, so that a person may turn round any number of times. The Jacobian is by
central differences of the model, all frames and features in one call.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shared.feature_sets import HERAKLES_NAMES, HERAKLES_RANGES
from shared.human import HumanModel

__all__ = ["FitConfig", "FitResult", "KeypointFit", "initial_guess", "POINT_NAMES", "REQUIRED"]

POINT_NAMES: tuple[str, ...] = HumanModel.JOINT_NAMES
"""The points the fit can use, named as the human model's joints (``pelvis``, ``torso``, ``neck``, ...)."""

REQUIRED = ("pelvis", "r_shoulder", "l_shoulder", "r_elbow", "r_wrist")
"""Points without which the 12 features are not determined (each frame must have them)."""

_YAW = HERAKLES_NAMES.index("pelvis_yaw")


def _default_prior() -> list[float]:
    # per feature, in 1/m or 1/rad: weak (a 1 cm residual outweighs 0.2 rad of prior), stronger on the torso twist
    return [0.01, 0.01, 0.01, 0.02, 0.05, 0.05, 0.05, 0.02, 0.02, 0.02, 0.05, 0.02]


@dataclass
class FitConfig:
    """Options of the keypoint fit.

    Attributes:
        iterations: Most Gauss-Newton steps per frame.
        tolerance_m: Stop when no feature moves more than this (m or rad) in a step.
        rel_tolerance: Stop when a step lowers the cost by less than this fraction of it. With noisy points the
            cost's floor is the noise, and steps that shave 0.1 % off it move the joints by micrometres: with
            1e-8 a frame of 2 cm noise took 6 steps (median) and up to the 30 allowed, 19.6 ms p99; with 1e-3,
            3 and 13, 13.9 ms, the joints' error unchanged (17.35 / 17.32 mm; clean points 0.035 mm both).
        prior: ``(12,)`` weight of each feature's pull towards the prior (previous frame).
        bounds: Feature name -> ``(low, high)``; features are kept inside.
        damping: Initial Levenberg-Marquardt damping.
        left_out: Points the fit does not use, and whose residual it does not report (NaN, as if unobserved). By
            default the left arm's: no feature moves the model's left arm (it is rigid on the torso, as in the
            paper's model), while a person's moves; fitted, a left arm raised 30 deg forward tilted the fitted
            torso by 0.29 rad with a 6 cm residual, which the tracker accepted, and past about 40 deg its residual
            refused every frame.
    """

    iterations: int = 30
    tolerance_m: float = 1e-4
    rel_tolerance: float = 1e-3
    prior: list[float] = field(default_factory=_default_prior)
    bounds: dict[str, tuple[float, float]] = field(default_factory=lambda: dict(HERAKLES_RANGES))
    damping: float = 1e-3
    left_out: tuple[str, ...] = ("l_elbow", "l_wrist", "l_hand")


@dataclass
class FitResult:
    """A fit's outcome per frame.

    Attributes:
        features: ``(B, 12)`` the fitted features.
        residual_m: ``(B, J)`` distance of each observed point from the fitted model's (NaN where not observed).
        iterations: Steps taken (the most over the batch).
        refused: ``(S, T)`` frames :meth:`KeypointFit.fit_sequences` did not take, their fit over its
            ``max_residual_m`` (None without one).
    """

    features: np.ndarray
    residual_m: np.ndarray
    iterations: int
    refused: np.ndarray | None = None

    @property
    def rms_m(self) -> np.ndarray:
        """``(B,)`` root mean square of the observed points' residuals."""
        return np.sqrt(np.nanmean(self.residual_m ** 2, axis=-1))


def initial_guess(points: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """A first guess of the features from the pelvis and shoulders: position, yaw; everything else 0.

    Args:
        points: ``(B, J, 3)`` observations in :data:`POINT_NAMES` order.
        observed: ``(B, J)`` which are observed.
    """
    names = list(POINT_NAMES)
    f = np.zeros((points.shape[0], 12))
    f[:, 0:3] = points[:, names.index("pelvis")]
    right, left = points[:, names.index("r_shoulder")], points[:, names.index("l_shoulder")]
    across = left - right  # the body's +y
    f[:, 3] = np.arctan2(-across[:, 0], across[:, 1])  # yaw: +y rotated by yaw is `across`
    ok = observed[:, names.index("r_shoulder")] & observed[:, names.index("l_shoulder")]
    f[~ok, 3] = 0.0
    return f


class KeypointFit:
    """Fits the 12 features to frames of keypoints.

    Args:
        config: Iterations, prior, bounds.
        model: The human model (default: :class:`shared.human.HumanModel`).
    """

    def __init__(self, config: FitConfig | None = None, model: HumanModel | None = None) -> None:
        self.config = config or FitConfig()
        self.model = model or HumanModel()
        unknown = set(self.config.bounds) - set(HERAKLES_NAMES)
        if unknown:
            raise ValueError(f"fit bounds: unknown features {sorted(unknown)} (features: {list(HERAKLES_NAMES)})")
        self.low = np.array([self.config.bounds.get(n, (-np.inf, np.inf))[0] for n in HERAKLES_NAMES])
        self.high = np.array([self.config.bounds.get(n, (-np.inf, np.inf))[1] for n in HERAKLES_NAMES])
        self.prior_weight = np.asarray(self.config.prior, dtype=np.float64)
        if self.prior_weight.shape != (12,):
            raise ValueError(f"fit prior: 12 weights, got {self.prior_weight.shape}")
        bad = [n for n in self.config.left_out if n not in POINT_NAMES or n in REQUIRED]
        if bad:
            raise ValueError(f"fit left_out: {bad} are not points the fit may leave out (points: "
                             f"{list(POINT_NAMES)}; required: {list(REQUIRED)})")
        self.used = np.array([n not in self.config.left_out for n in POINT_NAMES])  # (J,)

    def _residuals(self, f: np.ndarray, y: np.ndarray, w: np.ndarray, f0: np.ndarray) -> np.ndarray:
        p = self.model.joint_positions(f)  # (..., J, 3)
        r_pts = (p - y) * w[..., None]
        r_prior = (f - f0) * self.prior_weight
        return np.concatenate([r_pts.reshape(*f.shape[:-1], -1), r_prior], axis=-1)

    def fit(self, points: np.ndarray, observed: np.ndarray | None = None, prior: np.ndarray | None = None
            ) -> FitResult:
        """Fit a batch of frames.

        Args:
            points: ``(B, J, 3)`` observed positions in :data:`POINT_NAMES` order (NaN where missing).
            observed: ``(B, J)`` which points are observed (default: the finite ones).
            prior: ``(B, 12)`` features to start from and be pulled towards (default: :func:`initial_guess`).

        Returns:
            The fitted features and each point's residual (NaN where not observed or left out, ``config.left_out``).

        Raises:
            ValueError: Wrong shapes, or a frame without one of :data:`REQUIRED`.
        """
        y = np.asarray(points, dtype=np.float64)
        if y.ndim != 3 or y.shape[1:] != (len(POINT_NAMES), 3):
            raise ValueError(f"keypoints: expected shape (B, {len(POINT_NAMES)}, 3), got {y.shape}")
        obs = np.all(np.isfinite(y), axis=-1) if observed is None else np.asarray(observed, bool) & np.all(
            np.isfinite(y), axis=-1)
        obs = obs & self.used  # the points left out count as unobserved (config.left_out)
        names = list(POINT_NAMES)
        for req in REQUIRED:
            missing = np.flatnonzero(~obs[:, names.index(req)])
            if len(missing):
                raise ValueError(f"keypoints: {req} missing in {len(missing)} frame(s) (first: {missing[0]}); "
                                 f"required: {', '.join(REQUIRED)}")
        y = np.where(obs[..., None], y, 0.0)
        w = obs.astype(np.float64)
        f0 = initial_guess(y, obs) if prior is None else np.asarray(prior, dtype=np.float64).copy()
        # the yaw is an angle: a prior that has turned past a bound (a person turning round, a track followed
        # continuously) is fitted a whole number of turns back and returned as many turns on. Clipped at the bound
        # instead, the rest of a turn went into the torso's twist (a 450 deg turn fitted torso_z 1.58 rad, a review)
        turns = np.round(f0[:, _YAW] / (2 * np.pi))
        f0[:, _YAW] -= 2 * np.pi * turns
        f = np.clip(f0, self.low, self.high)
        mu = np.full(len(f), self.config.damping)
        r = self._residuals(f, y, w, f0)
        cost = np.sum(r ** 2, axis=-1)
        eps = 1e-6
        active = np.ones(len(f), dtype=bool)
        steps = 0
        for steps in range(1, self.config.iterations + 1):  # noqa: B007 (the count is reported)
            i = np.flatnonzero(active)  # a converged frame stays as it is: only the others are computed
            fi, yi, wi, f0i, ri, mui = f[i], y[i], w[i], f0[i], r[i], mu[i]
            shifts = np.eye(12) * eps  # (12, 12)
            fp = fi[:, None, :] + shifts  # (A, 12, 12)
            fm = fi[:, None, :] - shifts
            jac = (self._residuals(fp, yi[:, None], wi[:, None], f0i[:, None])
                   - self._residuals(fm, yi[:, None], wi[:, None], f0i[:, None])) / (2 * eps)  # (A, 12, R)
            jt = jac  # rows: d r / d f_k
            jtj = jt @ np.swapaxes(jt, -1, -2)  # (A, 12, 12)
            g = np.einsum("bkr,br->bk", jt, ri)
            a = jtj + mui[:, None, None] * (np.eye(12) * np.diagonal(jtj, axis1=-2, axis2=-1)[:, None, :]
                                            + np.eye(12) * 1e-9)
            delta = -np.linalg.solve(a, g[..., None])[..., 0]
            f_new = np.clip(fi + delta, self.low, self.high)
            r_new = self._residuals(f_new, yi, wi, f0i)
            cost_new = np.sum(r_new ** 2, axis=-1)
            better = cost_new <= cost[i]
            small = better & (cost[i] - cost_new <= self.config.rel_tolerance * cost[i])  # noisy points: at the optimum
            moved = np.max(np.abs(f_new - fi), axis=-1)  # the clipped step: at a bound a feature stays
            f[i] = np.where(better[:, None], f_new, fi)
            r[i] = np.where(better[:, None], r_new, ri)
            cost[i] = np.where(better, cost_new, cost[i])
            mu[i] = np.where(better, mui * 0.3, mui * 10.0)
            active[i] = ~((better & (moved < self.config.tolerance_m)) | small | (mu[i] > 1e6))
            if not active.any():
                break
        p = self.model.joint_positions(f)
        residual = np.where(obs, np.linalg.norm(p - y, axis=-1), np.nan)
        f[:, _YAW] += 2 * np.pi * turns
        return FitResult(f, residual, steps)

    def fit_sequences(self, points: np.ndarray, observed: np.ndarray | None = None,
                      max_residual_m: float | None = None) -> FitResult:
        """Fit recordings frame by frame, each frame warm-started from (and pulled towards) the one before.

        What a live tracker does, for many recordings at once: the first frame from :func:`initial_guess`, every
        later one from the previous fit, which keeps the fit on the same side of an ambiguity from one frame to
        the next and lets an unobserved point's degrees of freedom stay where they were.

        Args:
            points: ``(S, T, J, 3)`` S recordings of T frames (NaN where missing).
            observed: ``(S, T, J)`` (default: the finite points).
            max_residual_m: As the live tracker refuses a frame: one whose fit leaves its points further than this
                (rms) is marked in ``refused`` and is never a later frame's start, which begins from the last frame
                within it (or from :func:`initial_guess` before any). Without it, a sensor's glitch (one point
                15-25 m off in one frame) started the next frame from a wrecked fit, and every later frame of 1-3
                of 8 demonstrations was fitted over 5 cm off (a review). A refused frame is fitted once more from
                the first guess, and taken if that fits: from the last frame taken, long before, the fit may stop
                in another minimum. None: every frame starts the next.

        Returns:
            ``features (S, T, 12)``, ``residual_m (S, T, J)``, ``refused (S, T)`` (with ``max_residual_m``).
        """
        y = np.asarray(points, dtype=np.float64)
        if y.ndim != 4:
            raise ValueError(f"keypoint sequences: expected shape (S, T, J, 3), got {y.shape}")
        obs = np.all(np.isfinite(y), axis=-1) if observed is None else np.asarray(observed, bool)
        feats = np.zeros((*y.shape[:2], 12))
        resid = np.zeros(y.shape[:3])
        refused = np.zeros(y.shape[:2], dtype=bool)
        prior = np.zeros((y.shape[0], 12))
        started = np.zeros(y.shape[0], dtype=bool)  # a frame taken so far (its fit is the next frame's start)
        iterations = 0
        for t in range(y.shape[1]):
            start = (None if not started.any() else prior if started.all()
                     else np.where(started[:, None], prior, self._guess(y[:, t], obs[:, t])))
            res = self.fit(y[:, t], obs[:, t], start)
            f, r, iterations = res.features, res.residual_m, max(iterations, res.iterations)
            bad = np.zeros(len(f), dtype=bool) if max_residual_m is None else res.rms_m > max_residual_m
            if (again := np.flatnonzero(bad & started)).size:
                fresh = self.fit(y[again, t], obs[again, t])
                turns = np.round((prior[again, _YAW] - fresh.features[:, _YAW]) / (2 * np.pi))  # the track's turn
                fresh.features[:, _YAW] += 2 * np.pi * turns
                fits = fresh.rms_m <= max_residual_m
                f[again[fits]], r[again[fits]], bad[again[fits]] = fresh.features[fits], fresh.residual_m[fits], False
            feats[:, t], resid[:, t], refused[:, t] = f, r, bad
            prior = np.where(bad[:, None], prior, f)
            started |= ~bad
        return FitResult(feats, resid, iterations, refused if max_residual_m is not None else None)

    def _guess(self, points: np.ndarray, observed: np.ndarray) -> np.ndarray:
        """:func:`initial_guess` of ``points (B, J, 3)`` as :meth:`fit` makes it (missing points as unobserved)."""
        obs = np.asarray(observed, bool) & np.all(np.isfinite(points), axis=-1)
        return initial_guess(np.where(obs[..., None], points, 0.0), obs)
