"""Table I's scoring: which prediction each executed state was planned with; the comparison with the authors' runs."""

from __future__ import annotations

import types

import numpy as np
import pytest

from services.experiments.authors import TABLE1_RUNS
from services.experiments.harness import RunRecord
from services.experiments.heldout import CupClass
from services.experiments.interference import InterferenceConfig, InterferenceResult, RunScore, executed_belief


def test_each_state_is_scored_with_the_prediction_its_executed_plan_was_made_with() -> None:
    """Plan n - 1 runs during step n and was made with the grid of tick n - 2: the score read tick n - 1's posterior,
    one tick late, and so counted too little as 'accrued before recognition'."""
    ns = types.SimpleNamespace
    plans = [ns(tick=n, occupancy_tick=n - 1) for n in range(4)]  # plan n: the grid of tick n - 1 (-1: none yet)
    posteriors = {n: ns(posterior=np.array([p, 1 - p])) for n, p in enumerate((0.1, 0.3, 0.6, 0.9))}
    states = [ns(tick=n) for n in range(6)]  # ticks 4 and 5: the rest of the last plan (paper protocol)
    rec = RunRecord(plans=plans, states=states, posteriors=posteriors)
    assert executed_belief(rec, 0) == [0.0, 0.0, 0.1, 0.3, 0.6, 0.6]


def test_the_authors_comparison_puts_sample_standard_deviations_side_by_side() -> None:
    """Theirs were sample (ddof 1), ours population (ddof 0): 7.574 against 7.185 on the same 10 numbers."""
    cfg = InterferenceConfig(scene="pr2_two_cups_side_parallel", protocol="paper", demos=1, seeds=3)
    res = InterferenceResult(cfg, "paper", CupClass("blue_cup", 0, "compound_1", 0.4), [0])
    for seed, value in enumerate((1.0, 2.0, 4.0)):
        for name in ("basic", "least_penetration", "current"):
            res.runs.append(RunScore(0, seed, name, value, 0.0, 0.0, 0.1, 0.0, 0.0, None, (), 30.0))
    rows = res.authors_comparison()
    assert [r["planner"] for r in rows] == ["basic", "least_penetration"]
    assert rows[0]["ours"]["std"] == pytest.approx(np.std([1.0, 2.0, 4.0], ddof=1))
    assert rows[0]["authors"]["std"] == pytest.approx(np.std(TABLE1_RUNS["basic"][0], ddof=1))
    # Table I's (std) is the same sample deviation (it was the population one, 5 % smaller with 10 seeds)
    assert res.per_demo("basic") == ([pytest.approx(7 / 3)], [pytest.approx(np.std([1.0, 2.0, 4.0], ddof=1))])
