"""A small prediction model (3 classes, 8 demonstrations each, 4 Gaussians, 10 cm grid), trained once."""

from __future__ import annotations

import dataclasses

import numpy as np
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


@pytest.fixture(scope="session")
def small_model(small_library: MotionLibrary, scene: Scene) -> PredictionModel:
    cfg = TrainConfig(gmm=GMMConfig(n_components=4, max_iter=50), resolution=0.1, oversample=2)
    return train_model(small_library, scene, cfg, progress=False)


@pytest.fixture(scope="session")
def paper_model(small_model: PredictionModel) -> PredictionModel:
    """``small_model`` with the paper's 0/1 volumes (stored bit-packed as ``volumes``; the trainer's default is
    ``spread``): for the file-format tests of that layout."""
    return dataclasses.replace(small_model, volumes=(small_model.volumes > 0).astype(np.float32),
                               volume_method="paper")
