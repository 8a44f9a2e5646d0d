"""STOMP's pure steps: which rollouts are reused, and how they join the next iteration."""

from __future__ import annotations

import torch

from services.planner.stomp_steps import join_kept, keep_best


def test_keep_best_takes_the_least_total_costs_first() -> None:
    interior = torch.arange(4.0).reshape(1, 4, 1, 1).expand(1, 4, 3, 2)  # rollout r: all r
    cost = torch.tensor([[[3.0, 1.0], [0.5, 0.5], [float("nan"), 0.0], [2.0, 0.1]]])  # totals 4, 1, nan, 2.1
    kept, kept_cost = keep_best(interior, cost, 2)
    assert kept[0, :, 0, 0].tolist() == [1.0, 3.0]
    assert torch.equal(kept_cost[0], cost[0, [1, 3]])


def test_join_kept_is_the_new_and_kept_rollouts_then_the_best_of_them() -> None:
    g = torch.Generator().manual_seed(0)
    theta = torch.randn(2, 6, 3, generator=g)  # K = 2 goals, N = 6 free waypoints, D = 3
    eps, cost = torch.randn(2, 5, 6, 3, generator=g), torch.rand(2, 6, 8, generator=g)  # 5 new rollouts + theta
    kept_q, kept_cost = torch.randn(2, 4, 6, 3, generator=g), torch.rand(2, 4, 8, generator=g)
    first = join_kept(theta, eps, cost, None, None, 4)  # the first iteration: nothing kept yet
    assert torch.equal(first[0], eps) and torch.equal(first[1], cost)
    for got, want in zip(first[2:], keep_best(theta[:, None] + eps, cost[:, 1:], 4), strict=True):
        assert torch.equal(got, want)
    e, c, q2, c2 = join_kept(theta, eps, cost, kept_q, kept_cost, 4)
    assert torch.equal(e, torch.cat([eps, kept_q - theta[:, None]], 1))
    assert torch.equal(c, torch.cat([cost, kept_cost], 1))
    want_q, want_c = keep_best(theta[:, None] + e, c[:, 1:], 4)
    assert torch.equal(q2, want_q) and torch.equal(c2, want_c)
    assert torch.equal(c2[0], c[0, 1:][torch.argsort(c[0, 1:].sum(-1))[:4]])  # the least total costs first
