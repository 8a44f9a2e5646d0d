"""STOMP's pure steps: which rollouts are reused, how they join the next iteration, and one iteration's advance."""

from __future__ import annotations

import math

import pytest
import torch

from services.planner.stomp import _compiled
from services.planner.stomp_steps import advance, join_kept, keep_best, rollouts, update


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


def _iteration(keep: int, kept: bool) -> dict:
    """An iteration's inputs: K = 2, 5 new rollouts (+ theta), N = 6, D = 3; ``kept``: 4 from the one before."""
    g = torch.Generator().manual_seed(1)
    f = torch.float64
    theta = torch.rand(2, 6, 3, generator=g, dtype=f)
    lower, upper = torch.full((3,), 0.05, dtype=f), torch.full((3,), 0.95, dtype=f)
    return {"theta": theta, "eps": 0.1 * torch.randn(2, 5, 6, 3, generator=g, dtype=f),
            "cost": torch.rand(2, 6, 8, generator=g, dtype=f),
            "kept_q": torch.rand(2, 4, 6, 3, generator=g, dtype=f) if kept else None,
            "kept_cost": torch.rand(2, 4, 8, generator=g, dtype=f) if kept else None, "keep": keep,
            "best_cost": torch.tensor([math.inf, 1.0], dtype=f), "best_theta": theta.clone(), "lower": lower,
            "upper": upper, "m": torch.rand(6, 6, generator=g, dtype=f) / 6,
            "to_go": torch.tril(torch.ones(7, 6, dtype=f)), "sensitivity": 10.0,
            "noise": 0.1 * torch.randn(2, 5, 6, 3, generator=g, dtype=f),
            "start": torch.rand(2, 1, 3, generator=g, dtype=f), "goal": torch.rand(2, 1, 3, generator=g, dtype=f)}


def _three_steps(a: dict, steps: tuple = (join_kept, update, rollouts)) -> tuple:
    """What STOMP ran before :func:`advance`: join_kept (with reuse), update, then the next iteration's rollouts."""
    join, upd, roll = steps
    eps, cost, kept = a["eps"], a["cost"], (None, None)
    if a["keep"]:
        eps, cost, *kept = join(a["theta"], eps, cost, a["kept_q"], a["kept_cost"], a["keep"])
    theta, total, best_cost, best_theta = upd(a["theta"], eps, cost, a["best_cost"], a["best_theta"], a["lower"],
                                              a["upper"], a["m"], a["to_go"], a["sensitivity"])
    return (theta, total, best_cost, best_theta, *kept,
            *roll(theta, a["noise"], a["start"], a["goal"], a["lower"], a["upper"]))


@pytest.mark.parametrize(("keep", "kept"), [(4, True), (4, False), (0, False)],
                         ids=["reuse", "reuse-first-iteration", "no-reuse"])
def test_advance_is_the_three_steps_in_order_eager_and_compiled(keep: int, kept: bool) -> None:
    """The same numbers to the bit: eager as the three steps eager, compiled as the three compiled one by one."""
    a = _iteration(keep, kept)
    one_by_one = tuple(torch.compile(f, dynamic=False) for f in (join_kept, update, rollouts))
    pairs = ((advance(**a), _three_steps(a)), (_compiled("advance")(*a.values()), _three_steps(a, one_by_one)))
    for got, want in pairs:
        assert len(got) == len(want) == 8
        for i, (x, y) in enumerate(zip(got, want, strict=True)):
            assert (x is None and y is None) or torch.equal(x, y), f"result {i} differs"
    assert (want[4] is None) == (keep == 0)  # the kept rollouts: only with reuse
