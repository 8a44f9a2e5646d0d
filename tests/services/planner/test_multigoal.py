"""Algorithm 1 helpers: straight lines, arc-length resampling, reconnectPrevious, getBestTrajectory."""

from __future__ import annotations

import math

import pytest
import torch

from services.planner.multigoal import (
    best,
    choice_key,
    init_straight_lines,
    interpolate_path,
    project_onto_path,
    reconnect_previous,
    resample_path,
)

T = 40


def _blob(q: torch.Tensor) -> torch.Tensor:
    """(..., T, 2) -> (..., T) gaussian cost around (0.5, 0.5)."""
    return torch.exp(-((q - torch.tensor([0.5, 0.5])) ** 2).sum(-1) / (2 * 0.08**2))


def test_straight_lines_and_resampling() -> None:
    goals = torch.tensor([[1.0, 0.0], [0.0, 2.0]])
    lines = init_straight_lines(torch.tensor([0.0, 0.0]), goals, T)
    assert lines.shape == (2, T, 2)
    assert torch.equal(lines[:, 0], torch.zeros(2, 2)) and torch.equal(lines[:, -1], goals)
    # an L-shaped polyline padded with repeated vertices resamples to equal arc-length steps
    path = torch.tensor([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    out = resample_path(path, 21)
    steps = (out[1:] - out[:-1]).norm(dim=-1)
    assert torch.allclose(steps, torch.full((20,), 0.1), atol=1e-5)
    assert torch.equal(out[0], path[0]) and torch.equal(out[-1], path[-1])
    still = resample_path(torch.ones(4, 3), 5)  # zero length: every waypoint the same point
    assert torch.equal(still, torch.ones(5, 3))


def test_projection_and_interpolation() -> None:
    traj = init_straight_lines(torch.zeros(2), torch.tensor([[3.9, 0.0]]), T)[0]  # 0.1 per waypoint
    s, dist = project_onto_path(traj, torch.tensor([1.25, 0.2]))
    assert float(s) == pytest.approx(12.5, abs=1e-4) and float(dist) == pytest.approx(0.2, abs=1e-5)
    assert torch.allclose(interpolate_path(traj, s), torch.tensor([1.25, 0.0]), atol=1e-5)
    assert torch.equal(interpolate_path(traj, 100.0), traj[-1])


def test_reconnect_previous_starts_at_q_t_and_keeps_the_cheapest_line() -> None:
    start = torch.tensor([0.0, 0.0])
    goals = torch.tensor([[1.0, 0.0], [1.0, 1.0]])
    prev = init_straight_lines(start, goals, T)
    # goal 1's previous trajectory detours around the blob at (0.5, 0.5) through (0.9, 0.1)
    s = torch.linspace(0, 1, T)[:, None]
    knee = torch.tensor([0.9, 0.1])
    prev[1] = torch.where(s < 0.5, start + 2 * s * knee, knee + (2 * s - 1) * (goals[1] - knee))
    s_t = torch.tensor(15.5)
    q_t = interpolate_path(prev[0], s_t)  # robot moving along tau_best = goal 0

    def cost(q: torch.Tensor) -> torch.Tensor:
        return _blob(q)

    out = reconnect_previous(prev, 0, q_t, s_t, cost)
    assert out.shape == prev.shape
    assert torch.equal(out[:, 0], q_t.expand(2, 2))
    assert torch.allclose(out[:, -1], goals)
    # tau_best: the rest of the line, resampled
    assert torch.allclose(out[0], init_straight_lines(q_t, goals[:1], T)[0], atol=1e-5)
    # the other goal: cheaper than the straight line q_t -> goal through the blob
    line = init_straight_lines(q_t, goals[1:], T)
    assert float(cost(out[1:]).sum()) < 0.1 * float(cost(line).sum())
    # off tau_best: every goal is reconnected, still from q_t
    off = torch.tensor([0.3, -0.2])
    out2 = reconnect_previous(prev, 0, off, None, cost)
    assert torch.equal(out2[:, 0], off.expand(2, 2)) and torch.allclose(out2[:, -1], goals)


def test_reconnect_costs_no_candidate_of_the_followed_trajectory_and_the_others_as_alone() -> None:
    start = torch.tensor([0.0, 0.0])
    goals = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    prev = init_straight_lines(start, goals, T)
    prev[2, 5:25] += torch.tensor([0.3, 0.0])  # a bent path: its candidates differ
    s_t = torch.tensor(15.5)
    q_t = interpolate_path(prev[1], s_t)  # the robot follows goal 1's
    calls: list[tuple[int, ...]] = []

    def cost(q: torch.Tensor) -> torch.Tensor:
        calls.append(tuple(q.shape))
        return _blob(q)

    out = reconnect_previous(prev, 1, q_t, s_t, cost)
    assert calls == [(2, T, T, 2)]  # goals 0 and 2 only, T candidates each
    for g in (0, 2):  # each as if reconnected alone
        assert torch.equal(out[g], reconnect_previous(prev[g:g + 1], None, q_t, None, cost)[0])
    assert torch.allclose(out[1], init_straight_lines(q_t, goals[1:2], T)[0], atol=1e-5)
    calls.clear()
    one = reconnect_previous(prev[1:2], 0, q_t, s_t, cost)  # one goal, followed: nothing to cost
    assert calls == [] and torch.equal(one[0], out[1])


def test_best_picks_the_least_cost_valid_goal() -> None:
    total = torch.tensor([3.0, 1.0, 2.0, float("nan")])
    assert best(total, torch.tensor([True, True, True, True])) == 1
    assert best(total, torch.tensor([True, False, True, False])) == 2
    assert best(torch.full((2,), float("inf")), torch.tensor([False, True])) == 1
    with pytest.raises(ValueError, match="no valid goal"):
        best(total, torch.zeros(4, dtype=torch.bool))


def test_choice_by_human_cost_breaks_ties_by_total() -> None:
    valid = torch.ones(3, dtype=torch.bool)
    terms = {"human": torch.tensor([0.0, 0.0, 0.3]), "total": torch.tensor([5.0, 2.0, 1.0])}
    assert best(choice_key(terms, "human"), valid) == 1  # the two free goals tie: the cheaper of them
    assert best(choice_key(terms, "total"), valid) == 2
    terms["human"] = torch.tensor([0.2, 0.1, 0.3])
    assert best(choice_key(terms, "human"), valid) == 1
    terms["human"] = torch.tensor([0.2, 0.1, float("nan")])  # one NaN made every key inf: goal 0 was chosen
    assert best(choice_key(terms, "human"), valid) == 1
    # goal 0 invalid this step (its obstacle term inf) and of the least human cost: every valid key was inf, and the
    # first valid goal (1) won over the cheaper goal 2 (a review)
    terms = {"human": torch.tensor([0.001, 0.03, 0.0167]), "total": torch.tensor([math.inf, 0.5, 0.4])}
    valid = torch.tensor([False, True, True])
    assert best(choice_key(terms, "human", valid), valid) == 2
