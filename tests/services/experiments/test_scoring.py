"""One run's score: which prediction each executed state was planned with."""

from __future__ import annotations

import types

import numpy as np

from services.experiments.harness import RunRecord
from services.experiments.scoring import executed_belief


def test_each_state_is_scored_with_the_prediction_its_executed_plan_was_made_with() -> None:
    """Plan n - 1 runs during step n and was made with the grid of tick n - 2: the score read tick n - 1's posterior,
    one tick late, and so counted too little as 'accrued before recognition'."""
    ns = types.SimpleNamespace
    plans = [ns(tick=n, occupancy_tick=n - 1) for n in range(4)]  # plan n: the grid of tick n - 1 (-1: none yet)
    posteriors = {n: ns(posterior=np.array([p, 1 - p])) for n, p in enumerate((0.1, 0.3, 0.6, 0.9))}
    states = [ns(tick=n) for n in range(6)]  # ticks 4 and 5: the rest of the last plan (paper protocol)
    rec = RunRecord(plans=plans, states=states, posteriors=posteriors)
    assert executed_belief(rec, 0) == [0.0, 0.0, 0.1, 0.3, 0.6, 0.6]
