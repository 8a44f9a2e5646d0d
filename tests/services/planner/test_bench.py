"""The bench's cost-reached-against-iterations summary (services/planner/bench.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.planner.bench import convergence, main


def test_bench_convergence_ratios() -> None:
    h = np.array([[4.0, 2.0], [3.0, 1.0], [2.0, 1.5], [2.0, 1.0]])  # (I + 1, K): best so far 6, 4, 3, 3
    assert convergence([h], (0, 1, 2, 3)) == [2.0, 1.333, 1.0, 1.0]
    assert convergence([np.zeros((4, 2))], (0, 3)) == [1.0, 1.0]  # every goal reached: cost 0 throughout


def test_the_json_lists_only_the_checkpoints_reached(capsys) -> None:
    """With --iterations 5 the checkpoints were 0, 5, ..., 50 beside two costs per list."""
    assert main(["--k", "1", "--steps", "1", "--iterations", "5", "--rollouts", "4", "--reuse", "1",
                 "--waypoints", "10", "--no-compile", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["checkpoints"] == [0, 5]
    assert all(len(c) == 2 for c in report["cost_cold"] + report["cost_warm"])


def test_the_memory_help_names_the_k_the_code_measures(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "peak RSS of a planning process with the largest K of --k" in text and "K=8" not in text
