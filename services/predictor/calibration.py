"""The posterior temperature tau chosen for a library by cross-validation (``foresight train``).

``p(C_m | xi) = softmax_m(ln p(xi | C_m) / tau)`` (:func:`services.predictor.gmm.posterior_from_log_likelihood`).
The summed log-likelihood of ~100 strongly correlated samples counts the same evidence many times;
how many depends on the library (its size, class count, demonstration length), so tau is picked
per library: the demonstrations of every class are dealt round-robin into ``folds`` folds; for each
fold every class's mixture is refitted without that fold's demonstrations and the fold's
demonstrations are scored at executed fractions 10%, 20%, ..., 100%; the tau of a grid with the
least mean log-loss of the true class (``-ln p(true class | prefix)``, averaged over the
demonstrations and the fractions) is chosen.

A held-out demonstration's summed log-likelihood under one class's mixture depends on that mixture and that
demonstration only, and the report trains one model per held-out demonstration: each refits one class, so all
but one of every fold's mixtures are the ones the previous model scored with. The scores are therefore kept per
process by the mixture's parameters and the demonstration's data (:class:`_PrefixScorer`): a held-out model
scores only its refitted class, the same numbers to the bit (each class's column is computed as the stacked
bank computes it, with the same padding; tested).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
from sklearn.mixture import GaussianMixture

from .gmm import DEFAULT_TEMPERATURE, GMMError, MixtureBank, posterior_from_log_likelihood
from .volumes import digest

__all__ = ["TEMPERATURE_GRID", "CV_FRACTIONS", "TemperatureChoice", "choose_temperature", "log_loss", "fold_mixtures",
           "FoldFitError"]

TEMPERATURE_GRID = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 150.0, 200.0, 300.0, 500.0, 1000.0)
CV_FRACTIONS = tuple(round(0.1 * i, 1) for i in range(1, 11))
DEFAULT_FOLDS = 3


@dataclass(frozen=True)
class TemperatureChoice:
    """The chosen tau and how it was chosen.

    Attributes:
        temperature: The chosen tau.
        method: ``"cross-validated"`` or why not (too few demonstrations, a fixed value).
        folds: Folds used (0: none).
        mean_log_loss: Mean log-loss of the true class for every tau of the grid.
    """

    temperature: float
    method: str
    folds: int = 0
    mean_log_loss: dict[float, float] = field(default_factory=dict)

    def describe(self) -> str:
        """One line for ``foresight train``'s output."""
        if not self.mean_log_loss:
            return f"temperature {self.temperature:g} ({self.method})"
        best = self.mean_log_loss[self.temperature]
        return (f"temperature {self.temperature:g} ({self.method}, {self.folds}-fold, mean log-loss {best:.3f}; "
                f"tau = 1: {self.mean_log_loss.get(1.0, float('nan')):.3f})")


_SCORES: dict[str, np.ndarray] = {}
"""Summed log-likelihoods at the scored prefixes, by mixture and demonstration (:class:`_PrefixScorer`)."""
_SCORES_MAX = 500_000  # entries of 10 floats: about 60 MB at most, then the memo starts again


class _PrefixScorer:
    """One class mixture's summed log-likelihood of a demonstration's prefixes, memoised per process.

    Args:
        mixture: The fitted class mixture.
        components: The Gaussians of the stacked bank it is scored beside (its padding: the same float sums).
    """

    def __init__(self, mixture: GaussianMixture, components: int) -> None:
        self.mixture = mixture
        self.components = components
        self.key = digest(mixture.weights_, mixture.means_, mixture.covariances_, components)
        self._bank: MixtureBank | None = None

    def scores(self, x: np.ndarray, ends: np.ndarray, x_key: str) -> np.ndarray:
        """``(P,)`` ``sum_{t <= e} ln p(x_t | mixture)`` for each ``e`` of ``ends (P,)``; ``x`` is ``(T, D)``.

        ``x_key`` is ``digest(x, ends)``, computed once by the caller for every class's scorer.
        """
        key = self.key + x_key
        out = _SCORES.get(key)
        if out is None:
            if self._bank is None:
                self._bank = MixtureBank.from_sklearn([self.mixture], components=self.components)
            out = np.cumsum(self._bank.log_likelihood(x)[:, 0])[ends]
            if len(_SCORES) >= _SCORES_MAX:
                _SCORES.clear()
            _SCORES[key] = out
        return out


def fold_mixtures(feats: list[list[np.ndarray]], fit: Callable[[np.ndarray], GaussianMixture],
                  folds: int) -> Iterator[tuple[list[list[int]], list[GaussianMixture]]]:
    """The folds: for each, the held-out demonstrations of every class and every class's mixture fitted without them.

    Demonstration j of a class is in fold ``j % folds``; a fold holding none is skipped. The temperature's
    cross-validation and the novelty test (:mod:`services.predictor.novelty`) hold out the same folds, so a cached
    ``fit`` fits each fold's mixtures once for both.

    Args:
        feats: Per class, the encoded ``(T, D)`` feature vectors of each training demonstration.
        fit: Fits one class mixture to stacked ``(N, D)`` vectors.
        folds: Number of folds.

    Yields:
        ``(held, mixtures)``: per class the indices held out, and per class its mixture.
    """
    for k in range(folds):
        held = [[j for j in range(len(f)) if j % folds == k] for f in feats]
        if any(held):
            yield held, [_fit_without(fit, f, held[m], m, k) for m, f in enumerate(feats)]


def _fit_without(fit: Callable[[np.ndarray], GaussianMixture], demos: list[np.ndarray], held: list[int], m: int,
                 fold: int) -> GaussianMixture:
    """Class ``m``'s mixture without its demonstrations ``held``; a fit that fails says which class and fold.

    The whole class had samples enough and a fold without one of its demonstrations did not: ``foresight train``
    ended in a traceback saying only "cannot fit 20 Gaussians to 15 samples" (a review).
    """
    try:
        return fit(np.vstack([d for j, d in enumerate(demos) if j not in held]))
    except GMMError as exc:
        raise FoldFitError(m, held, fold, str(exc)) from None


class FoldFitError(GMMError):
    """A class's mixture that cannot be fitted without one cross-validation fold's demonstrations.

    Attributes:
        class_index: The class (its index in the library); ``held``: the demonstrations left out; ``fold``.
    """

    def __init__(self, class_index: int, held: list[int], fold: int, why: str) -> None:
        self.class_index, self.held, self.fold = class_index, held, fold
        super().__init__(f"class #{class_index} without its demonstration(s) {held} (cross-validation fold {fold}, "
                         f"for the temperature and the novelty threshold): {why}; fewer Gaussians (--components) or "
                         "more demonstrations per class")

    def naming(self, class_name: str) -> str:
        """The message with the class's name for its index."""
        return str(self).replace(f"class #{self.class_index} ", f"class {class_name} ", 1)


def log_loss(cum: np.ndarray, labels: np.ndarray, temperature: float) -> float:
    """Mean ``-ln p(true class | prefix)`` over ``cum (N, F, M)`` summed log-likelihoods (floored at 1e-12)."""
    p = posterior_from_log_likelihood(cum, temperature=temperature)
    true = np.take_along_axis(p, labels[:, None, None], axis=2)[..., 0]
    return float(-np.log(np.maximum(true, 1e-12)).mean())


def choose_temperature(feats: list[list[np.ndarray]], fit: Callable[[np.ndarray], GaussianMixture],
                       folds: int = DEFAULT_FOLDS, grid: tuple[float, ...] = TEMPERATURE_GRID,
                       fractions: tuple[float, ...] = CV_FRACTIONS) -> TemperatureChoice:
    """Pick tau by ``folds``-fold cross-validation of the mean log-loss.

    Args:
        feats: Per class, the encoded ``(T, D)`` feature vectors of each training demonstration.
        fit: Fits one class mixture to stacked ``(N, D)`` vectors (the trainer's, possibly cached).
        folds: Number of folds (>= 2).
        grid: Candidate temperatures.
        fractions: Executed fractions each held-out demonstration is scored at.

    Returns:
        The choice; :data:`services.predictor.gmm.DEFAULT_TEMPERATURE` when a class has fewer than 2
        demonstrations (nothing to hold out).
    """
    if min(len(f) for f in feats) < 2 or folds < 2:
        return TemperatureChoice(DEFAULT_TEMPERATURE, "default: a class has fewer than 2 demonstrations")
    cums, labels = [], []
    for held, mixtures in fold_mixtures(feats, fit, folds):
        scorers = [_PrefixScorer(g, max(g.n_components for g in mixtures)) for g in mixtures]
        for m, js in enumerate(held):
            for j in js:
                n = len(feats[m][j])
                ends = np.clip(np.rint(np.asarray(fractions) * n).astype(int), 1, n) - 1
                x_key = digest(feats[m][j], ends)  # once per demonstration, for every class's scorer
                cums.append(np.stack([s.scores(feats[m][j], ends, x_key) for s in scorers], axis=-1))  # (P, M)
                labels.append(m)
    cum, lab = np.array(cums), np.array(labels)
    losses = {float(t): log_loss(cum, lab, t) for t in grid}
    best = min(grid, key=lambda t: losses[float(t)])
    return TemperatureChoice(float(best), "cross-validated", folds, losses)
