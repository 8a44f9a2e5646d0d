"""Gaussian mixture regression (Calinon et al.): the expected motion of a class given time.

For a mixture over ``[t, y]`` with components ``(pi_k, mu_k, Sigma_k)``, the regression of ``y`` on
``t`` is

    h_k(t)        = pi_k N(t; mu_k^t, Sigma_k^tt) / sum_j pi_j N(t; mu_j^t, Sigma_j^tt)
    E[y | t]      = sum_k h_k(t) (mu_k^y + Sigma_k^yt (Sigma_k^tt)^-1 (t - mu_k^t))
    Cov[y | t]    = sum_k h_k(t) (Sigma_k^yy - Sigma_k^yt (Sigma_k^tt)^-1 Sigma_k^ty
                                  + m_k m_k^T) - E E^T      (m_k: the k-th conditional mean)
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

__all__ = ["gmr"]


def gmr(weights: np.ndarray, means: np.ndarray, covariances: np.ndarray, t: np.ndarray,
        in_dims: int = 1, return_covariance: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Condition a Gaussian mixture on its first ``in_dims`` dimensions.

    Args:
        weights: ``(K,)`` mixing weights (zero weights are ignored).
        means: ``(K, D)`` component means.
        covariances: ``(K, D, D)`` full covariances.
        t: ``(N,)`` or ``(N, in_dims)`` query inputs.
        in_dims: Number of leading input dimensions (1: time).
        return_covariance: Also return the conditional covariances.

    Returns:
        ``(N, D - in_dims)`` conditional means, and ``(N, D - in_dims, D - in_dims)`` covariances
        when asked.
    """
    w = np.asarray(weights, dtype=np.float64)
    mu = np.asarray(means, dtype=np.float64)
    cov = np.asarray(covariances, dtype=np.float64)
    keep = w > 0
    w, mu, cov = w[keep], mu[keep], cov[keep]
    q = np.asarray(t, dtype=np.float64).reshape(-1, in_dims)              # (N, I)
    i = slice(0, in_dims)
    o = slice(in_dims, mu.shape[1])
    s_ii = cov[:, i, i]                                                   # (K, I, I)
    s_oi = cov[:, o, i]                                                   # (K, O, I)
    s_ii_inv = np.linalg.inv(s_ii)
    diff = q[:, None, :] - mu[None, :, i]                                 # (N, K, I)
    maha = np.einsum("nki,kij,nkj->nk", diff, s_ii_inv, diff)
    _, logdet = np.linalg.slogdet(s_ii)
    log_resp = np.log(w)[None] - 0.5 * (maha + logdet[None] + in_dims * np.log(2 * np.pi))
    h = np.exp(log_resp - logsumexp(log_resp, axis=1, keepdims=True))     # (N, K)
    gain = np.einsum("koi,kij->koj", s_oi, s_ii_inv)                      # (K, O, I)
    cond = mu[None, :, o] + np.einsum("koj,nkj->nko", gain, diff)         # (N, K, O)
    mean = np.einsum("nk,nko->no", h, cond)
    if not return_covariance:
        return mean
    s_oo = cov[:, o, o] - np.einsum("koj,kpj->kop", gain, s_oi)           # (K, O, O)
    second = np.einsum("nk,kop->nop", h, s_oo) + np.einsum("nk,nko,nkp->nop", h, cond, cond)
    return mean, second - np.einsum("no,np->nop", mean, mean)
