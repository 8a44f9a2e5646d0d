"""Multi-goal replanning helpers of Algorithm 1 (Mainprice & Berenson, IROS 2013, section V-B/C).

``init_straight_lines`` seeds one trajectory per goal, ``reconnect_previous`` adapts the previous
step's K trajectories to the configuration the robot will have reached (Fig. 5) and ``best`` is
getBestTrajectory. All functions are pure torch, batched, and keep trajectories within the convex
joint-limit box whenever their inputs are (straight lines and resampling only interpolate).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

__all__ = ["init_straight_lines", "resample_path", "interpolate_path", "project_onto_path",
           "reconnect_previous", "best", "choice_key"]


def init_straight_lines(q_start: torch.Tensor, goals: torch.Tensor, waypoints: int) -> torch.Tensor:
    """The paper's initStraightLines: joint-space straight lines from the start to every goal.

    Args:
        q_start: ``(D,)`` or ``(K, D)`` start configuration(s).
        goals: ``(K, D)`` goal configurations.
        waypoints: T, the number of waypoints (start and goal included).

    Returns:
        ``(K, T, D)`` equally spaced waypoints from ``q_start`` to each goal.
    """
    s = torch.linspace(0.0, 1.0, waypoints, device=goals.device, dtype=goals.dtype)[:, None]  # (T, 1)
    q_start = q_start.expand_as(goals)
    return q_start[:, None] + s * (goals - q_start)[:, None]


def resample_path(path: torch.Tensor, waypoints: int) -> torch.Tensor:
    """Resample piecewise-linear joint-space paths to equally spaced (arc-length) waypoints.

    Zero-length segments are skipped, so repeated points may pad a path to a fixed length.

    Args:
        path: ``(..., P, D)`` polyline vertices, P >= 2.
        waypoints: T, the number of output waypoints.

    Returns:
        ``(..., T, D)``: first and last vertex kept, the rest equally spaced along the polyline (all
        equal to the first vertex if the path has zero length).
    """
    seg = path[..., 1:, :] - path[..., :-1, :]  # (..., P-1, D)
    seg_len = seg.norm(dim=-1)  # (..., P-1)
    cum = torch.cat([torch.zeros_like(seg_len[..., :1]), seg_len.cumsum(-1)], -1)  # (..., P)
    u = torch.linspace(0.0, 1.0, waypoints, device=path.device, dtype=path.dtype)
    target = u * cum[..., -1:]  # (..., T)
    idx = (torch.searchsorted(cum.contiguous(), target.contiguous(), right=True) - 1).clamp(0, path.shape[-2] - 2)
    start_len = torch.gather(cum, -1, idx)
    length = torch.gather(seg_len, -1, idx)
    frac = ((target - start_len) / length.clamp_min(1e-12)).clamp(0.0, 1.0)  # (..., T)
    gidx = idx[..., None].expand(*idx.shape, path.shape[-1])
    a = torch.gather(path, -2, gidx)
    b = torch.gather(path, -2, gidx + 1)
    out = a + frac[..., None] * (b - a)
    # exact endpoints (float round-off in the cumulative sum must not move the goal)
    return torch.cat([path[..., :1, :], out[..., 1:-1, :], path[..., -1:, :]], -2)


def interpolate_path(traj: torch.Tensor, s: torch.Tensor | float) -> torch.Tensor:
    """Configuration at a fractional waypoint index along a trajectory.

    Args:
        traj: ``(T, D)`` waypoints.
        s: Fractional index in ``[0, T-1]`` (clamped).

    Returns:
        ``(D,)`` linear interpolation between waypoints ``floor(s)`` and ``floor(s) + 1``.
    """
    t = traj.shape[0]
    s = torch.as_tensor(s, dtype=traj.dtype, device=traj.device).clamp(0, t - 1)
    i = s.floor().long().clamp(max=t - 2)
    f = s - i
    return traj[i] + f * (traj[i + 1] - traj[i])


def project_onto_path(traj: torch.Tensor, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Nearest point of a piecewise-linear trajectory to a configuration.

    Args:
        traj: ``(T, D)`` waypoints.
        q: ``(D,)`` configuration.

    Returns:
        ``(s, dist)``: 0-d tensors, the fractional waypoint index of the nearest point and the
        joint-space distance to it.
    """
    a, b = traj[:-1], traj[1:]  # (T-1, D)
    ab = b - a
    u = (((q - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp_min(1e-12)).clamp(0.0, 1.0)  # (T-1,)
    dist = (a + u[:, None] * ab - q).norm(dim=-1)
    i = torch.argmin(dist)
    return i.to(traj.dtype) + u[i], dist[i]


def reconnect_previous(trajs: torch.Tensor, best_index: int | None, q_t: torch.Tensor,
                       s_t: torch.Tensor | float | None,
                       cost_fn: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor:
    """The paper's reconnectPrevious (Fig. 5): restart every goal's previous trajectory at ``q_t``.

    For the goal of tau_best (``best_index``, when the robot follows it: ``s_t`` given) the result is
    the remaining part of tau_best after ``q_t``, resampled to T waypoints. For every other goal, the
    straight line from ``q_t`` to each waypoint j of its previous trajectory, followed by the rest of
    that trajectory (j..T-1), is a candidate; the candidates of all these goals (T each) are resampled to T
    waypoints, costed in one call of ``cost_fn`` and the cheapest candidate per goal is kept. tau_best's own
    candidates are not costed while the robot follows it (with one goal, nothing is).

    Args:
        trajs: ``(K, T, D)`` previous trajectories (each ending at its goal).
        best_index: Index of tau_best in ``trajs``, or None (no previous choice).
        q_t: ``(D,)`` configuration the robot will have reached when the new plan starts.
        s_t: Fractional waypoint index of ``q_t`` along ``trajs[best_index]``, or None when the robot
            is not on tau_best (then tau_best's goal is reconnected like the others).
        cost_fn: ``q (K', R', T, D) -> (K', R', T)`` per-waypoint total cost (here K' goals reconnected, R' = T
            candidates each).

    Returns:
        ``(K, T, D)`` trajectories starting exactly at ``q_t`` and ending at the previous goals.
    """
    k, t, d = trajs.shape
    q_t = q_t.to(trajs)
    j = torch.arange(t, device=trajs.device)
    follow = best_index is not None and s_t is not None
    # the goals reconnected by candidates: all but tau_best's while the robot follows it (its T candidates, as
    # many trajectories as 17 STOMP iterations cost at 101 waypoints, would be replaced by the rest of tau_best)
    others = torch.tensor([g for g in range(k) if not (follow and g == best_index)], dtype=torch.long,
                          device=trajs.device)
    out = trajs.clone()
    if len(others):
        prev = trajs[others]  # (K', T, D)
        # candidate c of goal g: vertices [q_t, q_t, ..., q_t (c times), trajs[g, c], ..., trajs[g, T-1]]
        keep = (j[None, :] >= j[:, None])  # (C=T, T): vertex i of candidate c is trajs[g, i] when i >= c
        verts = torch.where(keep[None, :, :, None], prev[:, None], q_t)  # (K', C, T, D)
        verts = torch.cat([q_t.expand(len(others), t, 1, d), verts], 2)  # (K', C, T+1, D)
        cand = resample_path(verts, t)  # (K', C, T, D)
        total = cost_fn(cand).sum(-1)  # (K', C)
        total = torch.nan_to_num(total, nan=float("inf"))
        pick = torch.argmin(total, dim=1)  # (K',)
        out[others] = cand[torch.arange(len(others), device=trajs.device), pick]  # (K', T, D)
    if follow:
        s_t = torch.as_tensor(s_t, dtype=trajs.dtype, device=trajs.device)
        rest = torch.where((j > s_t)[:, None], trajs[best_index], q_t)  # (T, D)
        out[best_index] = resample_path(torch.cat([q_t[None], rest], 0), t)
    out[:, 0] = q_t
    return out


def best(total: torch.Tensor, valid: torch.Tensor) -> int:
    """The paper's getBestTrajectory: index of the least total cost among the valid goals.

    Args:
        total: ``(K,)`` total costs.
        valid: ``(K,)`` bool, goals that may be chosen.

    Returns:
        The chosen index.

    Raises:
        ValueError: If no goal is valid.
    """
    if not bool(valid.any()):
        raise ValueError("no valid goal to choose from")
    masked = torch.where(valid, torch.nan_to_num(total, nan=float("inf")), torch.full_like(total, float("inf")))
    if not bool(torch.isfinite(masked).any()):  # all valid costs infinite: first valid goal
        return int(torch.nonzero(valid)[0, 0])
    return int(torch.argmin(masked))


def choice_key(terms: dict[str, torch.Tensor], goal_choice: str, valid: torch.Tensor | None = None) -> torch.Tensor:
    """``(K,)`` what the least-cost goal is chosen by (``PlannerConfig.goal_choice``).

    ``total``: the total cost. ``human``: the least human-occupancy cost among the ``valid (K,)`` goals (default:
    all); among the goals tied on it (to float32 rounding; e.g. all 0 before the human is anywhere near) the least
    total cost, as the authors' path cost adds 0.002 x length. Goals that do not tie get inf. (An invalid goal with
    the least human cost made every valid goal's key inf, and the first valid goal won whatever its cost.)
    """
    if goal_choice == "total":
        return terms["total"]
    h = torch.nan_to_num(terms["human"], nan=math.inf)  # one NaN made the minimum NaN, no goal tied: goal 0 won
    if valid is not None:
        h = torch.where(valid, h, h.new_tensor(math.inf))
    tied = h <= h.min() + 1e-6 * h.min().abs().clamp_min(1.0)  # float32: equal to rounding
    return torch.where(tied, terms["total"], h.new_tensor(math.inf))
