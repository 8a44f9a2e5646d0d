"""A small prediction model (3 classes, 8 demonstrations each, 4 Gaussians, 10 cm grid), trained once."""

from __future__ import annotations

import dataclasses

import pytest

from services.predictor.gmm import GMMConfig
from services.predictor.model import PredictionModel
from services.predictor.train import TrainConfig, train_model
from shared.library import MotionLibrary
from shared.scene import Scene, load_scene
from shared.synthetic import generate_library


@pytest.fixture(scope="session")
def small_library() -> MotionLibrary:
    return generate_library(n_classes=3, n_demos=8, seed=1)


@pytest.fixture(scope="session")
def scene() -> Scene:
    return load_scene(None)


SMALL = TrainConfig(gmm=GMMConfig(n_components=4, max_iter=50), resolution=0.1, oversample=2)
_FITS: dict = {}  # the two models below share their class mixtures


@pytest.fixture(scope="session")
def small_model(small_library: MotionLibrary, scene: Scene) -> PredictionModel:
    """The trainer's default volume (``demos``)."""
    return train_model(small_library, scene, SMALL, progress=False, fit_cache=_FITS)


@pytest.fixture(scope="session")
def paper_model(small_library: MotionLibrary, scene: Scene) -> PredictionModel:
    """The same mixtures with the paper's volume (0/1 along the mean motion, stored bit-packed as ``volumes``)."""
    return train_model(small_library, scene, dataclasses.replace(SMALL, volume="paper"), progress=False,
                       fit_cache=_FITS)


def _two_of_three(library: MotionLibrary) -> MotionLibrary:
    demos = [d for d in library.demos if d.label < 2]
    return dataclasses.replace(library, class_names=library.class_names[:2], demos=demos)


@pytest.fixture(scope="session")
def two_class_model(small_library, scene) -> PredictionModel:
    """Trained on two of the small library's three classes: the third is a motion it never saw."""
    return train_model(_two_of_three(small_library), scene, dataclasses.replace(SMALL, novelty_quantile=0.0),
                       progress=False)
