"""One Gaussian mixture per motion class (paper IV.A-IV.C) and their batched log-likelihood.

Training uses scikit-learn's ``GaussianMixture`` (full covariances, k-means initialisation, seeded);
the fitted parameters of all M classes are then stacked into one :class:`MixtureBank` whose
:meth:`MixtureBank.log_likelihood` scores a posture under every class at once. The query of the
paper, ``ln p(xi|C_m) = sum_t ln p(xi_t|C_m)``, is kept incrementally by the predictor core
(``services.predictor.core.PredictorCore``): each new posture adds its own term only, so the work per
pose is constant.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp
from sklearn.exceptions import ConvergenceWarning
from sklearn.mixture import GaussianMixture

__all__ = ["DEFAULT_TEMPERATURE", "GMMConfig", "GMMError", "fit_class_gmm", "MixtureBank",
           "posterior_from_log_likelihood"]

DEFAULT_TEMPERATURE = 150.0
"""Default posterior temperature tau (see :func:`posterior_from_log_likelihood`): the least mean log-loss
of the true class under leave-one-out on the synthetic library (`foresight eval recognition`); on the
paper's library it cuts the mean log-loss from 7.7 (tau = 1) to 1.16 (docs/prediction.md)."""


class GMMError(ValueError):
    """A class mixture that cannot be fitted to its data (too few samples, not finite); the text says why."""


@dataclass(frozen=True)
class GMMConfig:
    """Options of the per-class Gaussian mixtures.

    Attributes:
        n_components: Gaussians per class (the paper: 20). ``0`` picks the number per class by BIC
            among ``bic_candidates``.
        reg_covar: Added to the covariance diagonals (numerical floor; in the feature units).
        max_iter: EM iterations at most.
        n_init: k-means/EM restarts; the best is kept.
        tol: EM convergence threshold on the mean log-likelihood gain.
        seed: Random seed of the k-means initialisation.
        bic_candidates: Component counts tried when ``n_components == 0``.
    """

    n_components: int = 20
    reg_covar: float = 1e-3
    max_iter: int = 100
    n_init: int = 1
    tol: float = 1e-3
    seed: int = 0
    bic_candidates: tuple[int, ...] = (5, 10, 15, 20, 30)

    def validate(self) -> None:
        """Raise ``ValueError`` on a bad option."""
        if self.n_components < 0:
            raise ValueError(f"components must be >= 0 (0 = by BIC), got {self.n_components}")
        if not (self.reg_covar > 0 and math.isfinite(self.reg_covar)):
            raise ValueError(f"reg_covar must be > 0, got {self.reg_covar}")
        if self.max_iter < 1 or self.n_init < 1:
            raise ValueError("max_iter and n_init must be >= 1")
        if not (self.tol >= 0 and math.isfinite(self.tol)):
            raise ValueError(f"tol must be a finite number >= 0, got {self.tol}")
        if self.n_components == 0 and (not self.bic_candidates or min(self.bic_candidates) < 1):
            raise ValueError(f"bic_candidates must be component counts >= 1 to choose among (components 0: by BIC), "
                             f"got {tuple(self.bic_candidates)}")


def _fit(data: np.ndarray, k: int, cfg: GMMConfig) -> GaussianMixture:
    gmm = GaussianMixture(n_components=k, covariance_type="full", init_params="kmeans", reg_covar=cfg.reg_covar,
                          max_iter=cfg.max_iter, n_init=cfg.n_init, tol=cfg.tol, random_state=cfg.seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # an unconverged EM is still a usable fit
        return gmm.fit(data)


def fit_class_gmm(data: np.ndarray, cfg: GMMConfig) -> GaussianMixture:
    """Fit the mixture of one class.

    Args:
        data: ``(N, D)`` feature vectors of all the class's demonstrations, stacked.
        cfg: Options.

    Returns:
        The fitted ``GaussianMixture`` (``weights_``, ``means_``, ``covariances_``).

    Raises:
        GMMError: If there are fewer samples than components or the data is not finite.
    """
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2 or not np.all(np.isfinite(data)):
        raise GMMError(f"GMM data must be a finite (N, D) array, got shape {data.shape}")
    ks = [cfg.n_components] if cfg.n_components > 0 else [k for k in cfg.bic_candidates if k < len(data)]
    if not ks:
        raise GMMError(f"cannot choose the number of Gaussians by BIC among {tuple(cfg.bic_candidates)} with "
                         f"{len(data)} samples: each needs more samples than Gaussians")
    if ks[0] > len(data):
        raise GMMError(f"cannot fit {cfg.n_components} Gaussians to {len(data)} samples")
    best, best_bic = None, np.inf
    for k in ks:
        gmm = _fit(data, k, cfg)
        bic = gmm.bic(data) if len(ks) > 1 else 0.0
        if bic < best_bic or best is None:
            best, best_bic = gmm, bic
    assert best is not None
    return best


class MixtureBank:
    """The M class mixtures, stacked for batched scoring (classes with fewer Gaussians are padded).

    Args:
        weights: ``(M, K)`` mixing weights (0 for padding).
        means: ``(M, K, D)`` component means.
        covariances: ``(M, K, D, D)`` full covariances (identity for padding).
    """

    def __init__(self, weights: np.ndarray, means: np.ndarray, covariances: np.ndarray) -> None:
        self.weights_ = np.asarray(weights, dtype=np.float64)
        self.means_ = np.asarray(means, dtype=np.float64)
        self.covariances_ = np.asarray(covariances, dtype=np.float64)
        m, k, d = self.means_.shape
        if self.weights_.shape != (m, k) or self.covariances_.shape != (m, k, d, d):
            raise ValueError(f"mixture shapes disagree: weights {self.weights_.shape}, means {self.means_.shape}, "
                             f"covariances {self.covariances_.shape}")
        chol = np.linalg.cholesky(self.covariances_)                      # (M, K, D, D) lower
        eye = np.broadcast_to(np.eye(d), chol.shape)
        # precision Cholesky factor U with U U^T = Sigma^-1: U = L^-T
        self.prec_chol_ = np.swapaxes(np.linalg.solve(chol, eye), -1, -2)  # (M, K, D, D)
        log_det = np.sum(np.log(np.diagonal(self.prec_chol_, axis1=-2, axis2=-1)), axis=-1)  # (M, K)
        with np.errstate(divide="ignore"):
            self._log_norm = np.log(self.weights_) + log_det - 0.5 * d * math.log(2 * math.pi)  # (M, K)
        self._flat_prec = self.prec_chol_.reshape(m * k, d, d)
        self._flat_means = self.means_.reshape(m * k, d)

    @classmethod
    def from_sklearn(cls, mixtures: list[GaussianMixture], components: int | None = None) -> MixtureBank:
        """Stack fitted scikit-learn mixtures (one per class), padding to the largest K (or to ``components``)."""
        k = max(g.n_components for g in mixtures)
        if components is not None:
            if components < k:
                raise ValueError(f"cannot pad mixtures of {k} Gaussians to {components}")
            k = components
        d = mixtures[0].means_.shape[1]
        m = len(mixtures)
        w = np.zeros((m, k))
        mu = np.zeros((m, k, d))
        cov = np.broadcast_to(np.eye(d), (m, k, d, d)).copy()
        for i, g in enumerate(mixtures):
            n = g.n_components
            w[i, :n], mu[i, :n], cov[i, :n] = g.weights_, g.means_, g.covariances_
        return cls(w, mu, cov)

    def log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """``ln p(x_t | C_m)`` of each sample under each class.

        Args:
            x: ``(..., D)`` feature vectors.

        Returns:
            ``(..., M)`` log densities.
        """
        x = np.asarray(x, dtype=np.float64)
        m, k, d = self.means_.shape
        lead = x.shape[:-1]
        xs = x.reshape(-1, d)                                               # (N, D)
        diff = xs[:, None, :] - self._flat_means[None]                      # (N, MK, D)
        y = np.einsum("nkd,kde->nke", diff, self._flat_prec)                # (N, MK, D)
        maha = np.einsum("nke,nke->nk", y, y).reshape(-1, m, k)             # (N, M, K)
        out = logsumexp(self._log_norm[None] - 0.5 * maha, axis=-1)         # (N, M)
        return out.reshape(*lead, m)


def posterior_from_log_likelihood(log_likelihood: np.ndarray, log_prior: np.ndarray | None = None,
                                  temperature: float = 1.0) -> np.ndarray:
    """``p(C_m | xi)`` from ``ln p(xi | C_m)`` by log-sum-exp normalisation (uniform prior by default).

    With ``temperature`` tau the posterior is ``softmax(ln p(xi | C_m) / tau + ln prior)``: the
    summed log-likelihood of T strongly correlated samples counts the same evidence many times
    over, and tau > 1 deflates it (tau = 1 is the paper's posterior; the argmax never changes).

    Args:
        log_likelihood: ``(..., M)``.
        log_prior: ``(M,)`` optional class log priors.
        temperature: tau > 0, the divisor of the log-likelihoods.

    Returns:
        ``(..., M)`` posteriors summing to 1 over the last axis; in a row without a finite value (after the prior)
        the prior, normalised (uniform without one).

    Raises:
        ValueError: If ``temperature`` is not a finite number > 0, or a log-likelihood is NaN or +inf (no
            probability follows from it: the rows came out NaN).
    """
    if not (temperature > 0 and math.isfinite(temperature)):
        raise ValueError(f"temperature must be a finite number > 0, got {temperature}")
    ll = np.asarray(log_likelihood, dtype=np.float64)
    bad = np.isnan(ll) | (ll == np.inf)
    if bad.any():
        raise ValueError(f"log-likelihoods must be finite or -inf, got {int(bad.sum())} NaN or +inf of {ll.size}")
    # each row shifted by its maximum before the division: ll / 1e-306 overflowed to -inf in every class, and the
    # row fell back to uniform where one class leads (the shift leaves the softmax as it is)
    top = np.max(ll, axis=-1, keepdims=True, initial=-np.inf)
    ll = ll - np.where(np.isfinite(top), top, 0.0)
    if temperature != 1.0:
        with np.errstate(over="ignore"):  # a tiny tau: every class behind the leader goes to -inf, one-hot
            ll = ll / temperature
    if log_prior is not None:
        ll = ll + log_prior
    known = np.isfinite(ll).any(axis=-1, keepdims=True)  # a row with no finite value: no evidence, the prior
    ll = np.where(known, ll, 0.0)
    return np.where(known, np.exp(ll - logsumexp(ll, axis=-1, keepdims=True)), _no_evidence(log_prior, ll.shape[-1]))


def _no_evidence(log_prior: np.ndarray | None, m: int) -> np.ndarray:
    """``(M,)`` the posterior of a row without evidence: the prior (uniform without one, or one with no finite value).

    Uniform gave mass to the classes of prior 0 where every class with a prior had no likelihood.
    """
    p = None if log_prior is None else np.asarray(log_prior, dtype=np.float64)
    if p is None or not np.isfinite(p).any():
        return np.full(m, 1.0 / m)
    p = np.where(np.isfinite(p), p, -np.inf)
    return np.exp(p - logsumexp(p))
