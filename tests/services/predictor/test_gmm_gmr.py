from __future__ import annotations

import math

import numpy as np
import pytest
from sklearn.mixture import GaussianMixture

from services.predictor.gmm import GMMConfig, MixtureBank, fit_class_gmm, posterior_from_log_likelihood
from services.predictor.gmr import gmr


def _curve(t: np.ndarray) -> np.ndarray:
    return np.stack([np.sin(2 * np.pi * t / 100), 0.5 * (t / 100) ** 2], axis=-1)


def test_gmr_reproduces_known_curve() -> None:
    rng = np.random.default_rng(0)
    t = np.tile(np.arange(100.0), 20)
    y = _curve(t) + rng.normal(0, 0.02, (len(t), 2))
    g = fit_class_gmm(np.column_stack([t, y]), GMMConfig(n_components=12, reg_covar=1e-6))
    q = np.arange(5.0, 95.0)
    mean, cov = gmr(g.weights_, g.means_, g.covariances_, q, return_covariance=True)
    assert mean.shape == (len(q), 2) and cov.shape == (len(q), 2, 2)
    assert np.max(np.abs(mean - _curve(q))) < 0.06
    # the conditional spread is about the noise, and positive definite
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert np.median(np.sqrt(cov[:, 0, 0])) < 0.06


def test_gmr_single_gaussian_is_linear_regression() -> None:
    cov = np.array([[[4.0, 2.0], [2.0, 3.0]]])
    mean = gmr(np.array([1.0]), np.array([[1.0, -1.0]]), cov, np.array([3.0]))
    assert np.allclose(mean, [[-1.0 + 2.0 / 4.0 * 2.0]])


@pytest.mark.parametrize("in_dims", [1, 2])
def test_gmr_equals_direct_gaussian_conditioning(in_dims: int) -> None:
    """Mean and covariance against each component conditioned by hand, mixed by the law of total covariance: the
    between-component term of the covariance could be dropped and the tests above still passed (a review)."""
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(3)
    k, d = 3, 5
    weights = np.array([0.5, 0.3, 0.2])
    means = rng.normal(0.0, 1.0, (k, d))
    roots = rng.normal(0.0, 0.6, (k, d, d))
    covs = roots @ roots.transpose(0, 2, 1) + 0.1 * np.eye(d)
    x = rng.normal(0.0, 1.0, (7, in_dims))
    mean, cov = gmr(weights, means, covs, x[:, 0] if in_dims == 1 else x, in_dims=in_dims, return_covariance=True)
    i, o = slice(0, in_dims), slice(in_dims, d)
    for n, xn in enumerate(x):
        h = np.array([w * multivariate_normal(m[i], c[i, i]).pdf(xn) for w, m, c in zip(weights, means, covs,
                                                                                             strict=True)])
        h /= h.sum()
        mu = np.array([m[o] + c[o, i] @ np.linalg.solve(c[i, i], xn - m[i]) for m, c in zip(means, covs, strict=True)])
        sig = np.array([c[o, o] - c[o, i] @ np.linalg.solve(c[i, i], c[i, o]) for c in covs])
        want_mean = h @ mu
        want_cov = np.einsum("k,kab->ab", h, sig + np.einsum("ka,kb->kab", mu, mu)) - np.outer(want_mean, want_mean)
        np.testing.assert_allclose(mean[n], want_mean, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(cov[n], want_cov, rtol=1e-8, atol=1e-12)


def test_bank_matches_sklearn_and_posterior_sums_to_one() -> None:
    rng = np.random.default_rng(1)
    mixtures = [GaussianMixture(k, covariance_type="full", random_state=0).fit(rng.normal(i, 1.0 + i, (300, 4)))
                for i, k in enumerate((2, 3, 4))]
    bank = MixtureBank.from_sklearn(mixtures)
    x = rng.normal(1.0, 2.0, (50, 4))
    ll = bank.log_likelihood(x)
    ref = np.stack([g.score_samples(x) for g in mixtures], axis=1)
    assert np.allclose(ll, ref, atol=1e-8)
    post = posterior_from_log_likelihood(np.cumsum(ll, axis=0))
    assert np.all(post >= 0) and np.allclose(post.sum(axis=1), 1.0)
    # extreme log-likelihoods (thousands apart) still normalise
    post = posterior_from_log_likelihood(np.array([-1e5, -2e5, -1e5 - 3]))
    assert np.isclose(post.sum(), 1.0) and post[0] > 0.9


def test_tempered_posterior() -> None:
    rng = np.random.default_rng(4)
    ll = rng.normal(0.0, 50.0, (30, 5)).cumsum(axis=0)
    paper = posterior_from_log_likelihood(ll)
    # tau = 1 is the paper's posterior exactly
    assert np.array_equal(posterior_from_log_likelihood(ll, temperature=1.0), paper)
    for tau in (0.5, 3.0, 40.0):
        post = posterior_from_log_likelihood(ll, temperature=tau)
        assert np.all(post >= 0) and np.allclose(post.sum(axis=1), 1.0)
        assert np.array_equal(np.argmax(post, axis=1), np.argmax(paper, axis=1))  # argmax unchanged
        assert np.allclose(post, posterior_from_log_likelihood(ll / tau))
    # a higher temperature spreads the posterior (entropy grows)
    ent = [-(p * np.log(np.maximum(p, 1e-300))).sum(axis=1).mean()
           for p in (posterior_from_log_likelihood(ll, temperature=t) for t in (1.0, 5.0, 50.0))]
    assert ent[0] < ent[1] < ent[2]
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="temperature"):
            posterior_from_log_likelihood(ll, temperature=bad)


@pytest.mark.parametrize("bad", [[math.nan, 0.0, -1.0], [math.inf, 0.0, -1.0]])
def test_a_nan_or_infinite_log_likelihood_is_refused(bad) -> None:
    """They gave NaN rows ([nan, 0, -1] -> all NaN; [inf, 0, -1] -> [nan, 0, 0]) where a probability was promised."""
    with pytest.raises(ValueError, match="log-likelihoods must be finite or -inf, got 1 NaN or \\+inf of 3"):
        posterior_from_log_likelihood(np.array(bad))
    assert posterior_from_log_likelihood(np.array([-math.inf, 0.0, 0.0])).tolist() == [0.0, 0.5, 0.5]


def test_a_row_without_evidence_is_uniform_in_a_batch_too() -> None:
    """The fallback used to be global: a batch with one such row gave NaN there (and a NaN log loss)."""
    ll = np.array([[0.0, -2.0], [-np.inf, -np.inf]])
    p = posterior_from_log_likelihood(ll)
    np.testing.assert_allclose(p[1], [0.5, 0.5])
    np.testing.assert_allclose(p[0], posterior_from_log_likelihood(ll[0]))
    np.testing.assert_allclose(posterior_from_log_likelihood(ll[1]), [0.5, 0.5])


def test_too_few_samples_for_every_bic_candidate_names_the_candidates() -> None:
    """It said 'cannot fit 0 Gaussians to 5 samples'."""
    with pytest.raises(ValueError, match=r"by BIC among \(5, 10\) with 5 samples"):
        fit_class_gmm(np.random.default_rng(0).normal(size=(5, 2)), GMMConfig(n_components=0, bic_candidates=(5, 10)))


@pytest.mark.parametrize(("cfg", "match"), [
    (GMMConfig(tol=math.nan), "tol must be a finite number >= 0, got nan"),
    (GMMConfig(tol=-1.0), "tol must be a finite number >= 0"),
    (GMMConfig(n_components=0, bic_candidates=()), r"bic_candidates .* got \(\)"),
    (GMMConfig(n_components=0, bic_candidates=(0, 5)), r"bic_candidates .* got \(0, 5\)"),
])
def test_bad_gmm_options_are_named_before_any_fit(cfg, match) -> None:
    """A NaN tol passed and failed inside scikit-learn, naming its own parameter."""
    with pytest.raises(ValueError, match=match):
        cfg.validate()


def test_a_row_without_evidence_takes_the_prior_not_uniform() -> None:
    """Uniform gave half the mass to the class of prior 0 when the only class with a prior had no likelihood."""
    ll = np.array([[-math.inf, 0.0], [-1.0, -3.0]])
    prior = np.log([0.75, 0.25])
    p = posterior_from_log_likelihood(ll, prior)
    np.testing.assert_allclose(p[0], [0.0, 1.0])  # the evidence, where some class has both
    np.testing.assert_allclose(posterior_from_log_likelihood(np.array([0.0, -math.inf]), np.array([-math.inf, 0.0])),
                               [0.0, 1.0])
    np.testing.assert_allclose(posterior_from_log_likelihood(np.full(3, -math.inf), np.log([0.2, 0.3, 0.5])),
                               [0.2, 0.3, 0.5])
    np.testing.assert_allclose(posterior_from_log_likelihood(np.full(2, -math.inf), np.full(2, -math.inf)),
                               [0.5, 0.5])  # a prior without a finite value says nothing either


def test_a_tiny_temperature_gives_the_leader_everything() -> None:
    """ll / 1e-306 overflowed to -inf in every class: a uniform posterior where one class leads."""
    ll = np.array([[-1000.0, -1003.0, -math.inf], [-5.0, -5.0, -6.0]])
    for tau in (1e-306, 5e-324):
        np.testing.assert_array_equal(posterior_from_log_likelihood(ll, temperature=tau),
                                      [[1.0, 0.0, 0.0], [0.5, 0.5, 0.0]])
    np.testing.assert_allclose(posterior_from_log_likelihood(ll, temperature=150.0),
                               np.exp(ll / 150.0) / np.exp(ll / 150.0).sum(axis=1, keepdims=True))
