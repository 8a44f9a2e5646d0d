"""The tracker tests' reach: a synthetic demonstration with a second of rest before and after it."""

from __future__ import annotations

import numpy as np
import pytest

from shared.synthetic import generate_library


@pytest.fixture(scope="module")
def reach() -> np.ndarray:
    """``(T, 12)``: a synthetic demonstration with a second of rest before and after it."""
    d = generate_library(seed=0).demos[0]
    return np.concatenate([np.repeat(d.features[:1], 30, 0), d.features, np.repeat(d.features[-1:], 40, 0)])
