"""A small in-memory motion library for the replayer tests."""

from __future__ import annotations

import numpy as np
import pytest

from shared.library import Demonstration, MotionLibrary


def make_library(n_classes: int = 3, n_demos: int = 4, t: int = 12, seed: int = 0) -> MotionLibrary:
    """Plausible demonstrations whose features encode (label, index, sample) so order is checkable."""
    demos = []
    for m in range(n_classes):
        for k in range(n_demos):
            f = np.zeros((t + k, 12))
            f[:, 0] = 1 + m
            f[:, 1] = 1 + k
            f[:, 2] = 0.5 + 0.01 * np.arange(t + k)
            f[:, 3:] = 0.1 * np.random.default_rng(seed + 10 * m + k).normal(size=(t + k, 9))
            demos.append(Demonstration(m, f"class_{m}", k, f, f"test#{m}.{k}"))
    return MotionLibrary([f"class_{m}" for m in range(n_classes)], demos, [], "test library")


@pytest.fixture
def small_lib() -> MotionLibrary:
    return make_library()
