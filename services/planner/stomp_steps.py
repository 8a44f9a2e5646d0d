"""STOMP's iteration as pure tensor functions (:mod:`services.planner.stomp` runs them, compiled or eager).

1. :func:`rollouts`: the current trajectory and its noisy rollouts, clamped to the joint limits;
2. the caller costs them (and, with reuse, adds the previous iteration's best with their costs, :func:`keep_best`);
3. :func:`update`: keep the best, probabilities per waypoint, the smoothed update.

:func:`advance` is 2-3 and the next iteration's 1 in one function (what STOMP calls after each cost call).

:func:`finite_difference_matrix` is the STOMP paper's A (R = A^T A).
"""

from __future__ import annotations

import torch

__all__ = ["finite_difference_matrix", "rollouts", "with_ends", "finite", "update", "keep_best", "join_kept", "advance"]

_NONFINITE_COST = 1e9  # a rollout whose cost is NaN/inf is treated as this costly per waypoint


def finite_difference_matrix(n: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Acceleration finite differencing matrix A of the STOMP paper.

    Args:
        n: Number of free (interior) waypoints N.
        dtype: Result dtype.

    Returns:
        ``(N + 2, N)``: row i gives ``theta[i-2] - 2 theta[i-1] + theta[i]`` (theta outside 0..N-1 taken as 0),
        the acceleration at waypoint i of a deviation that leaves the fixed start (waypoint 0) and goal (N + 1)
        in place. ``theta^T A^T A theta`` sums the squared accelerations at all N + 2 waypoints, the start's and
        goal's too (``theta[0]^2`` and ``theta[N-1]^2``, as if held still beyond the ends). ``R = A^T A`` only
        shapes STOMP's exploration noise and update; the smoothness the planner minimises is
        :func:`services.planner.costs.acceleration_cost` (``w_smooth`` x the squared accelerations at the
        interior waypoints of the trajectory itself), not ``0.5 theta^T R theta``.
    """
    a = torch.zeros(n + 2, n, dtype=dtype)
    idx = torch.arange(n)
    a[idx, idx] = 1.0
    a[idx + 1, idx] = -2.0
    a[idx + 2, idx] = 1.0
    return a


def rollouts(theta: torch.Tensor, noise: torch.Tensor, start: torch.Tensor, goal: torch.Tensor,
             lower: torch.Tensor, upper: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Step 1: the current trajectory and its noisy rollouts, clamped to the joint limits, with their endpoints.

    Args:
        theta: ``(K, N, D)`` current free waypoints.
        noise: ``(K, R, N, D)`` this iteration's exploration noise.
        start: ``(K, 1, D)`` fixed start.
        goal: ``(K, 1, D)`` fixed goal.
        lower: ``(D,)`` lower joint limits.
        upper: ``(D,)`` upper joint limits.

    Returns:
        ``(q (K, R + 1, N + 2, D), eps (K, R, N, D))``: row 0 of ``q`` is ``theta``, rows 1.. the rollouts;
        ``eps`` is the noise actually applied (after clamping).
    """
    noisy = torch.clamp(theta[:, None] + noise, lower, upper)
    eps = noisy - theta[:, None]
    return with_ends(torch.cat([theta[:, None], noisy], 1), start, goal), eps


def with_ends(interior: torch.Tensor, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """``interior (K, R', N, D)`` free waypoints, ``start``, ``goal (K, 1, D)`` -> ``(K, R', N + 2, D)``."""
    k, r = interior.shape[:2]
    return torch.cat([start[:, None].expand(k, r, 1, -1), interior, goal[:, None].expand(k, r, 1, -1)], 2)


def finite(cost: torch.Tensor) -> torch.Tensor:
    """``cost`` (any shape) with NaN/inf replaced by a very large finite cost (such a rollout is never preferred)."""
    return torch.nan_to_num(cost, nan=_NONFINITE_COST, posinf=_NONFINITE_COST, neginf=-_NONFINITE_COST)


def update(theta: torch.Tensor, eps: torch.Tensor, cost: torch.Tensor, best_cost: torch.Tensor,
           best_theta: torch.Tensor, lower: torch.Tensor, upper: torch.Tensor, m: torch.Tensor,
           to_go: torch.Tensor | None, sensitivity: float
           ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Steps 2-4 after the cost call: keep the best, probabilities per waypoint, the smoothed update.

    Args:
        theta: ``(K, N, D)`` current free waypoints.
        eps: ``(K, R, N, D)`` the noise applied to the rollouts.
        cost: ``(K, R + 1, N + 2)`` per-waypoint cost (row 0: ``theta``); NaN/inf count as very costly, and a
            rollout with one takes no part in the update.
        best_cost: ``(K,)`` the least total cost so far.
        best_theta: ``(K, N, D)`` its waypoints.
        lower: ``(D,)`` lower joint limits.
        upper: ``(D,)`` upper joint limits.
        m: ``(N, N)`` the smoothing matrix M.
        to_go: ``(N + 1, N)`` cost-to-go summation matrix, or None (rank by each waypoint's own cost).
        sensitivity: h.

    Returns:
        ``(theta', total (K,) cost of theta, best_cost', best_theta')``.
    """
    ok = torch.isfinite(cost[:, 1:, 1:]).all(-1, keepdim=True)  # (K, R, 1): the rollouts costed finite
    cost = finite(cost)
    total = cost[:, 0].sum(-1)  # (K,)
    better = total < best_cost
    best_cost = torch.where(better, total, best_cost)
    best_theta = torch.where(better[:, None, None], theta, best_theta)
    # S(r, i) = sum_{j >= i} q(r, j) (goal included), or the free waypoints' own costs
    s = cost[:, 1:, 1:] @ to_go if to_go is not None else cost[:, 1:, 1:-1]  # (K, R, N)
    # 3. probabilities per waypoint over the rollouts costed finite (none: no update); a NaN/inf rollout scaled
    # among them would stretch the range (s_max - s_min) so far that every other rollout weighed the same
    s_min = torch.where(ok, s, torch.inf).amin(1, keepdim=True)
    s_max = torch.where(ok, s, -torch.inf).amax(1, keepdim=True)
    scaled = -sensitivity * (s - s_min) / (s_max - s_min).clamp_min(1e-12)
    p = torch.softmax(torch.where(ok, scaled, -torch.inf), dim=1).nan_to_num(0.0)
    # 4. update: probability-weighted noise, smoothed by M, kept within the limits
    delta = torch.matmul(m, (p[..., None] * eps).sum(1))  # (K, N, D)
    return torch.clamp(theta + delta, lower, upper), total, best_cost, best_theta


def keep_best(interior: torch.Tensor, cost: torch.Tensor, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``n`` rollouts of least total cost, to be reused in the next iteration (``StompConfig.reuse``).

    Args:
        interior: ``(K, R, N, D)`` the rollouts' free waypoints (absolute, not noise).
        cost: ``(K, R, T)`` their per-waypoint costs.
        n: Rollouts kept (<= R).

    Returns:
        ``(interior (K, n, N, D), cost (K, n, T))``, least total cost first.
    """
    order = torch.argsort(finite(cost).sum(-1), dim=1, stable=True)[:, :n]  # (K, n); ties: the first rollout
    kept = torch.gather(interior, 1, order[..., None, None].expand(-1, -1, *interior.shape[2:]))
    return kept, torch.gather(cost, 1, order[..., None].expand(-1, -1, cost.shape[-1]))



def join_kept(theta: torch.Tensor, eps: torch.Tensor, cost: torch.Tensor, kept_q: torch.Tensor | None,
              kept_cost: torch.Tensor | None, keep: int) -> tuple[torch.Tensor, ...]:
    """With reuse (``StompConfig.reuse``): the kept rollouts join the new ones, and the best are kept for the next.

    One function, so that compiled it is one call per iteration instead of a dozen eager ops.

    Args:
        theta: ``(K, N, D)`` current free waypoints.
        eps: ``(K, R', N, D)`` the noise applied to this iteration's new rollouts.
        cost: ``(K, R' + 1, N + 2)`` their per-waypoint costs (row 0: ``theta``).
        kept_q: ``(K, keep, N, D)`` the previous iteration's best rollouts (absolute), or None (first iteration).
        kept_cost: ``(K, keep, N + 2)`` their costs, or None.
        keep: Rollouts kept for the next iteration.

    Returns:
        ``(eps, cost, kept_q', kept_cost')``: the noise and costs of every rollout of this iteration (the
        kept ones last), for :func:`update`, and its ``keep`` best (:func:`keep_best`).
    """
    if kept_q is not None and kept_cost is not None:
        eps = torch.cat([eps, kept_q - theta[:, None]], 1)
        cost = torch.cat([cost, kept_cost], 1)
    return (eps, cost, *keep_best(theta[:, None] + eps, cost[:, 1:], keep))


def advance(theta: torch.Tensor, eps: torch.Tensor, cost: torch.Tensor, kept_q: torch.Tensor | None,
            kept_cost: torch.Tensor | None, keep: int, best_cost: torch.Tensor, best_theta: torch.Tensor,
            lower: torch.Tensor, upper: torch.Tensor, m: torch.Tensor, to_go: torch.Tensor | None, sensitivity: float,
            noise: torch.Tensor, start: torch.Tensor, goal: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
    """The rest of an iteration after its cost call, and the next iteration's rollouts, as one function.

    With reuse (``keep`` > 0) :func:`join_kept`, then :func:`update`, then :func:`rollouts` of the updated
    trajectory with the next iteration's noise: the same operations in the same order as three separate calls,
    so that compiled they are one call per iteration (a compiled call costs tens of microseconds on a CPU
    before any work, about as much as these three steps' arithmetic).

    Args:
        theta: ``(K, N, D)`` current free waypoints.
        eps: ``(K, R', N, D)`` the noise applied to this iteration's new rollouts.
        cost: ``(K, R' + 1, N + 2)`` their per-waypoint costs (row 0: ``theta``).
        kept_q: ``(K, keep, N, D)`` the previous iteration's best rollouts, or None (first iteration, no reuse).
        kept_cost: ``(K, keep, N + 2)`` their costs, or None.
        keep: Rollouts kept for the next iteration (0: no reuse).
        best_cost: ``(K,)`` the least total cost so far.
        best_theta: ``(K, N, D)`` its waypoints.
        lower: ``(D,)`` lower joint limits.
        upper: ``(D,)`` upper joint limits.
        m: ``(N, N)`` the smoothing matrix M.
        to_go: ``(N + 1, N)`` cost-to-go summation matrix, or None.
        sensitivity: h.
        noise: ``(K, R'', N, D)`` the next iteration's exploration noise.
        start: ``(K, 1, D)`` fixed start.
        goal: ``(K, 1, D)`` fixed goal.

    Returns:
        ``(theta', total, best_cost', best_theta', kept_q', kept_cost', q', eps')``: :func:`update`'s four
        results, :func:`join_kept`'s kept rollouts (None without reuse) and :func:`rollouts` of ``theta'``.
    """
    kept: tuple[torch.Tensor | None, torch.Tensor | None] = (None, None)
    if keep:
        eps, cost, kept_q, kept_cost = join_kept(theta, eps, cost, kept_q, kept_cost, keep)
        kept = (kept_q, kept_cost)
    theta, total, best_cost, best_theta = update(theta, eps, cost, best_cost, best_theta, lower, upper, m, to_go,
                                                 sensitivity)
    q, eps = rollouts(theta, noise, start, goal, lower, upper)
    return theta, total, best_cost, best_theta, *kept, q, eps
