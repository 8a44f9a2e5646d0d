"""The trainer's fit cache: fitted class mixtures, sweeps and volumes keyed by a digest of their data and options.

:func:`~services.predictor.train.train_model` passes every class fit, demonstration sweep and class volume
through a ``fit_cache`` mapping (:func:`cached`): a dict within one process, or the report's
:class:`~services.experiments.fit_store.FitStore`, which its worker processes share on disk. :func:`class_fit`
is the one key of a class fit, so the trainer's fits and the recognition's leave-one-out refits of the same data
are one entry.
"""

from __future__ import annotations

from collections.abc import Callable, MutableMapping
from typing import Any

import numpy as np

from .gmm import GMMConfig, fit_class_gmm
from .volumes import digest

__all__ = ["cached", "class_fit"]


def class_fit(data: np.ndarray, gmm: GMMConfig, cache: MutableMapping[str, Any] | None = None) -> Any:
    """``fit_class_gmm(data, gmm)`` through ``cache`` (None: fitted now), under the key every caller shares.

    The trainer's class fits and the recognition's leave-one-out refits of the same data and options are one
    entry: a held-out model's class mixture is the leave-one-out fit of that demonstration.

    Args:
        data: ``(N, D)`` the class's stacked feature vectors.
        gmm: Mixture options.
        cache: A fit cache (a dict, or the report's shared store).
    """
    if cache is None:
        return fit_class_gmm(data, gmm)
    return cached(cache, "gmm:" + digest(data, repr(gmm)), lambda: fit_class_gmm(data, gmm))


def cached(cache: MutableMapping[str, Any], key: str, make: Callable[[], Any]) -> Any:
    """``cache[key]``, made with ``make()`` if it is missing.

    A cache with a ``compute(key, make)`` method (the report's
    :class:`~services.experiments.fit_store.FitStore`, shared by its worker processes) makes each entry once
    across processes; a dict, once per process.
    """
    compute = getattr(cache, "compute", None)
    if compute is not None:
        return compute(key, make)
    if key not in cache:
        cache[key] = make()
    return cache[key]
