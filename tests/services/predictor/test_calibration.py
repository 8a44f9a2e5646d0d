"""The temperature's cross-validation: per-class scores memoised, the same numbers as the stacked bank's."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.mixture import GaussianMixture

from services.predictor import calibration
from services.predictor.calibration import CV_FRACTIONS, choose_temperature, log_loss
from services.predictor.gmm import GMMConfig, MixtureBank, fit_class_gmm
from services.predictor.volumes import digest


def _mixtures(rng: np.random.Generator) -> list[GaussianMixture]:
    return [GaussianMixture(k, covariance_type="full", random_state=0).fit(rng.normal(i, 1.0 + i, (300, 4)))
            for i, k in enumerate((2, 3, 4))]


def test_one_class_bank_padded_as_the_stack_gives_its_column_to_the_bit() -> None:
    """Batched equals looped: each class scored alone, padded to the stack's Gaussians, is the stack's column."""
    rng = np.random.default_rng(2)
    mixtures = _mixtures(rng)
    x = rng.normal(1.0, 2.0, (60, 4))
    stacked = MixtureBank.from_sklearn(mixtures).log_likelihood(x)                        # (60, 3)
    for c, g in enumerate(mixtures):
        alone = MixtureBank.from_sklearn([g], components=4).log_likelihood(x)[:, 0]
        assert np.array_equal(alone, stacked[:, c])


def test_padding_below_the_largest_mixture_is_refused() -> None:
    with pytest.raises(ValueError, match="cannot pad mixtures of 4 Gaussians to 3"):
        MixtureBank.from_sklearn(_mixtures(np.random.default_rng(3)), components=3)


def _feats(rng: np.random.Generator) -> list[list[np.ndarray]]:
    """3 classes x 5 demonstrations of 40 samples in 3 features (random walks from class-specific starts)."""
    return [[c + np.cumsum(rng.normal(0.0, 0.1, (40, 3)), axis=0) for _ in range(5)] for c in range(3)]


def _stacked_reference(feats: list[list[np.ndarray]], fit, folds: int = 3) -> dict[float, float]:
    """The cross-validation as it was before the memo: every held-out demonstration under the stacked bank."""
    cums, labels = [], []
    for k in range(folds):
        held = [[j for j in range(len(f)) if j % folds == k] for f in feats]
        bank = MixtureBank.from_sklearn([fit(np.vstack([f[j] for j in range(len(f)) if j % folds != k]))
                                         for f in feats])
        for m, js in enumerate(held):
            for j in js:
                ll = np.cumsum(bank.log_likelihood(feats[m][j]), axis=0)
                n = len(ll)
                cums.append(ll[np.clip(np.rint(np.asarray(CV_FRACTIONS) * n).astype(int), 1, n) - 1])
                labels.append(m)
    cum, lab = np.array(cums), np.array(labels)
    return {float(t): log_loss(cum, lab, t) for t in calibration.TEMPERATURE_GRID}


def test_a_held_out_model_scores_only_its_refitted_class(monkeypatch: pytest.MonkeyPatch) -> None:
    """One model per held-out demonstration refits one class: only that class's mixtures are scored again."""
    monkeypatch.setattr(calibration, "_SCORES", {})
    fits: dict[str, GaussianMixture] = {}
    cfg = GMMConfig(n_components=2)

    def fit(data: np.ndarray) -> GaussianMixture:
        key = digest(data)
        if key not in fits:
            fits[key] = fit_class_gmm(data, cfg)
        return fits[key]

    calls = []
    scored = MixtureBank.log_likelihood

    def counting(self: MixtureBank, x: np.ndarray) -> np.ndarray:
        calls.append(self.means_.shape[0])
        return scored(self, x)

    feats = _feats(np.random.default_rng(5))
    reference = _stacked_reference(feats, fit)
    monkeypatch.setattr(MixtureBank, "log_likelihood", counting)
    first = choose_temperature(feats, fit)
    assert first.mean_log_loss == reference  # exactly: the same sums as the stacked bank
    assert len(calls) == 15 * 3 and set(calls) == {1}  # each held-out demonstration under each class's mixture

    calls.clear()
    without = [feats[0][1:], feats[1], feats[2]]  # class 0's first demonstration held out: class 0 refitted
    second = choose_temperature(without, fit)
    singles = len(calls)
    assert second.mean_log_loss == _stacked_reference(without, fit)
    # class 0's fold mixtures score their folds' held-out demonstrations: 6 + 5 + 3, but its new fold 2 trains on
    # demonstrations 1, 2, 4, as its old fold 0 did, which scored demonstration 3 already: 13. Classes 1 and 2 score
    # class 0's 4 demonstrations, each now in another fold: 8. Everything else comes from the memo (45 before).
    assert singles == 13 + 8
