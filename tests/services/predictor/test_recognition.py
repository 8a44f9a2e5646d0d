"""Leave-one-out recognition through the trainer's fit cache: the same result, each class fit made once."""

from __future__ import annotations

import numpy as np
import pytest

from services.predictor import fit_cache
from services.predictor.gmm import GMMConfig
from services.predictor.recognition import leave_one_out
from services.predictor.train import TrainConfig, train_model
from shared.library import MotionLibrary
from shared.scene import Scene

GMM = GMMConfig(n_components=3, max_iter=30)


def test_the_refits_are_the_held_out_models_class_fits(small_library: MotionLibrary, scene: Scene,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    plain = leave_one_out(small_library, GMM, n_jobs=1, progress=False)
    fits: dict = {}
    held = small_library.by_class(1)[2]
    train_model(small_library, scene, TrainConfig(gmm=GMM, resolution=0.2, temperature=1.0),
                demos=[d for d in small_library.demos if d is not held], progress=False, fit_cache=fits)
    made = []
    fit = fit_cache.fit_class_gmm
    monkeypatch.setattr(fit_cache, "fit_class_gmm", lambda data, gmm: made.append(len(data)) or fit(data, gmm))
    shared = leave_one_out(small_library, GMM, n_jobs=1, progress=False, fit_cache=fits)
    assert np.array_equal(shared.log_likelihood, plain.log_likelihood) and shared.rates == plain.rates
    # 3 whole classes and 24 refits; the held-out model had fitted class 1 without `held` and classes 0 and 2 whole
    assert len(made) == 3 + 24 - 3
    made.clear()
    leave_one_out(small_library, GMM, n_jobs=1, progress=False, fit_cache=fits)  # a second time: all read
    assert made == []


def test_a_fit_cache_is_read_in_one_process(small_library: MotionLibrary) -> None:
    with pytest.raises(ValueError, match="n_jobs must be 1, got 2"):
        leave_one_out(small_library, GMM, n_jobs=2, progress=False, fit_cache={})
