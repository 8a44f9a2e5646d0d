"""STOMP's pure steps: which rollouts are reused, how they join the next iteration, and one iteration's advance."""

from __future__ import annotations

import math

import pytest
import torch

from services.planner.costs import acceleration_cost
from services.planner.stomp import _compiled
from services.planner.stomp_steps import advance, finite_difference_matrix, join_kept, keep_best, rollouts, update


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


def _update_args(cost: torch.Tensor, eps: torch.Tensor, to_go: bool) -> dict:
    """``update``'s arguments for K = 1, N = 6 free waypoints, D = 2 around ``cost (1, R + 1, 8)``."""
    f = torch.float64
    return {"theta": torch.full((1, 6, 2), 0.5, dtype=f), "eps": eps, "cost": cost,
            "best_cost": torch.tensor([math.inf], dtype=f), "best_theta": torch.zeros(1, 6, 2, dtype=f),
            "lower": torch.zeros(2, dtype=f), "upper": torch.ones(2, dtype=f), "m": torch.eye(6, dtype=f) / 2,
            "to_go": torch.tril(torch.ones(7, 6, dtype=f)) if to_go else None, "sensitivity": 10.0}


@pytest.mark.parametrize("to_go", [True, False])
def test_a_non_finite_rollout_takes_no_part_and_the_others_weigh_as_without_it(to_go: bool) -> None:
    g = torch.Generator().manual_seed(2)
    f = torch.float64
    cost, eps = torch.rand(1, 5, 8, generator=g, dtype=f), 0.1 * torch.randn(1, 4, 6, 2, generator=g, dtype=f)
    without = update(**_update_args(cost[:, [0, 1, 2, 4]], eps[:, [0, 1, 3]], to_go))[0]
    for bad in (float("nan"), math.inf):
        spoilt = cost.clone()
        spoilt[0, 3, :] = bad  # rollout 2 (row 3): non-finite at every waypoint
        got = update(**_update_args(spoilt, eps, to_go))[0]
        torch.testing.assert_close(got, without)  # before: the others all weighed 1/4, whatever their costs


def test_a_rollout_non_finite_at_one_waypoint_takes_no_part_anywhere() -> None:
    g = torch.Generator().manual_seed(3)
    f = torch.float64
    cost, eps = torch.rand(1, 5, 8, generator=g, dtype=f), 0.1 * torch.randn(1, 4, 6, 2, generator=g, dtype=f)
    spoilt = cost.clone()
    spoilt[0, 3, 4] = math.nan  # rollout 2 at free waypoint 3 (index 4 of 8: the start is index 0)
    for to_go in (True, False):
        got = update(**_update_args(spoilt, eps, to_go))[0]
        torch.testing.assert_close(got, update(**_update_args(cost[:, [0, 1, 2, 4]], eps[:, [0, 1, 3]], to_go))[0])


def test_no_finite_rollout_leaves_the_trajectory_where_it_was() -> None:
    g = torch.Generator().manual_seed(4)
    f = torch.float64
    cost, eps = torch.rand(1, 5, 8, generator=g, dtype=f), 0.1 * torch.randn(1, 4, 6, 2, generator=g, dtype=f)
    cost[0, 1:] = math.nan
    for to_go in (True, False):
        args = _update_args(cost, eps, to_go)
        got, total = update(**args)[:2]
        assert torch.equal(got, args["theta"]) and torch.isfinite(total).all()


def test_r_counts_the_accelerations_at_the_fixed_ends_which_the_smoothness_cost_does_not() -> None:
    """``theta^T R theta`` is the squared accelerations at all N + 2 waypoints of a deviation held still beyond the
    ends; the planner's smoothness (:func:`acceleration_cost`) sums only the interior ones (docstring of A)."""
    n = 6
    theta = torch.randn(n, 1, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    a = finite_difference_matrix(n)
    quadratic = float(theta.T @ a.T @ a @ theta)
    zero = theta.new_zeros(1, 1)
    held = torch.cat([zero, zero, theta, zero, zero])  # start and goal fixed (deviation 0), one still step beyond
    interior = float(acceleration_cost(torch.cat([zero, theta, zero])).sum())
    assert quadratic == pytest.approx(float(acceleration_cost(held).sum()))
    assert quadratic == pytest.approx(interior + float(theta[0, 0] ** 2 + theta[-1, 0] ** 2))
