"""STOMP's pure steps: which rollouts are reused."""

from __future__ import annotations

import torch

from services.planner.stomp_steps import keep_best


def test_keep_best_takes_the_least_total_costs_first() -> None:
    interior = torch.arange(4.0).reshape(1, 4, 1, 1).expand(1, 4, 3, 2)  # rollout r: all r
    cost = torch.tensor([[[3.0, 1.0], [0.5, 0.5], [float("nan"), 0.0], [2.0, 0.1]]])  # totals 4, 1, nan, 2.1
    kept, kept_cost = keep_best(interior, cost, 2)
    assert kept[0, :, 0, 0].tolist() == [1.0, 3.0]
    assert torch.equal(kept_cost[0], cost[0, [1, 3]])
