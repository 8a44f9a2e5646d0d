"""The bench's cost-reached-against-iterations summary (services/planner/bench.py)."""

from __future__ import annotations

import numpy as np

from services.planner.bench import convergence


def test_bench_convergence_ratios() -> None:
    h = np.array([[4.0, 2.0], [3.0, 1.0], [2.0, 1.5], [2.0, 1.0]])  # (I + 1, K): best so far 6, 4, 3, 3
    assert convergence([h], (0, 1, 2, 3)) == [2.0, 1.333, 1.0, 1.0]
    assert convergence([np.zeros((4, 2))], (0, 3)) == [1.0, 1.0]  # every goal reached: cost 0 throughout
