"""Which optimised paths may be published: those that do not pass through the static scene or the robot itself.

STOMP's obstacle term is a cost, not a constraint: a step cut short (the anytime minimum of iterations in real
time) or a goal behind an obstacle can end with waypoints inside the table, and such a path was published as
valid (a review: 3 of 12 goals under the table after 10 iterations, up to 2.8 cm deep), with
``goal_choice = "human"`` even chosen over a free one. :func:`path_penetration` checks each path densely
(every waypoint and ``substeps - 1`` configurations between two) against the scene's signed distance field and the
arm/body self-collision spheres, as the goals' IK solutions are checked (:meth:`StateCost.collision_free`); a goal
whose path collides is invalid for the step while another goal's path is free.

When no path is free, they are published as optimised (as they were before this check), with a warning: the
paper's side scene's first step leaves every path 2.8-4.5 cm in the table (its straight lines cross it by 1.6 and
6.9 cm), and refusing them left the executor without a first plan, the experiments without a run. The executor
follows a plan only until the next one, whose optimisation goes on from it; a plan that stays inside the scene is
then what the warning says. The warning says where the least deep path first goes in (:func:`first_contact`): in
real time's first plans, 2-6 s along paths each followed ~0.1 s before the next (docs/planner.md).

The robot's start is where it is: a path is refused only where a sphere goes deeper into the scene, or an arm/body
sphere pair deeper into each other, than that sphere or pair is at the start (a real robot's reading a millimetre
inside a modelled table would otherwise refuse every plan and leave the robot where it is); another sphere's contact
at the start excuses none.
"""

from __future__ import annotations

import logging
import math
import time

import torch

from .costs import StateCost
from .inputs import PlannerError

log = logging.getLogger("foresight.planner")

__all__ = ["path_penetration", "first_contact", "publishable", "invalid_reason", "SUBSTEPS", "TOLERANCE_M"]

SUBSTEPS = 4
"""Configurations checked per waypoint segment (linear in joint space): a segment moves a sphere ~5 cm at most."""

TOLERANCE_M = 1e-3
"""Penetration below this is rounding (the signed distance field's trilinear error is up to 1.5 voxels off the
analytic surface, docs/robot.md, but the same field scores the path, so only a real overlap reaches it)."""


def path_penetration(cost: object, paths: torch.Tensor, substeps: int = SUBSTEPS) -> torch.Tensor:
    """How far each path goes into the static scene or the robot itself beyond its start (m; 0: free).

    Args:
        cost: The planner's state cost (its scene field, spheres and self-collision groups); a cost of another kind
            (:class:`services.planner.protocols.PlannerCost`, a test's toy cost) models no collision: all 0.
        paths: ``(K, T, D)`` trajectories, waypoint 0 the start.
        substeps: Configurations per segment (``substeps - 1`` between two waypoints, plus the next waypoint).

    Returns:
        ``(K,)`` the deepest penetration after the start, each sphere or pair less its own at the start (m), 0
        where that is below :data:`TOLERANCE_M`.
    """
    k, t, _ = paths.shape
    if t < 2 or not isinstance(cost, StateCost):
        return paths.new_zeros(k)
    beyond = _beyond_start(cost, paths, substeps).amax(-1)
    return torch.where(beyond < TOLERANCE_M, torch.zeros_like(beyond), beyond)


def first_contact(cost: object, path: torch.Tensor, substeps: int = SUBSTEPS) -> float:
    """Where along ``path`` ``(T, D)`` a sphere or pair first goes deeper than at the start (0-1; nan: never)."""
    if len(path) < 2 or not isinstance(cost, StateCost):
        return math.nan
    inside = torch.nonzero(_beyond_start(cost, path[None], substeps)[0] >= TOLERANCE_M).flatten()
    return float(inside[0] + 1) / ((len(path) - 1) * substeps) if len(inside) else math.nan


def _beyond_start(cost: StateCost, paths: torch.Tensor, substeps: int) -> torch.Tensor:
    """``(K, (T-1) substeps)`` each dense configuration's deepest penetration beyond the start (m).

    Each sphere (in the scene) and each arm/body sphere pair (overlap) is measured against its own depth at the
    start (comparing the deepest of all with the start's deepest let a start with one sphere 2.9 cm in the table
    hide a path driving another 1.8 cm into it: a review's case).
    """
    k, _, d = paths.shape
    frac = torch.arange(1, substeps + 1, device=paths.device, dtype=paths.dtype) / substeps  # (S,)
    seg = paths[:, :-1, None] + frac[:, None] * (paths[:, 1:, None] - paths[:, :-1, None])  # (K, T-1, S, D)
    q = torch.cat([paths[:, :1], seg.reshape(k, -1, d)], 1)  # (K, 1 + (T-1) S, D)
    centers = cost.robot.sphere_centers(q)
    depth = (cost.radii - cost.sdf(centers[..., cost.spheres, :])).clamp(min=0)  # (K, N, spheres)
    if cost.has_self:
        overlap = (-cost.robot.self_collision_distance(centers)).flatten(-2).clamp(min=0)  # (K, N, A B)
        depth = torch.cat([depth, overlap], -1)
    return (depth[:, 1:] - depth[:, :1]).clamp(min=0).amax(-1)


def publishable(cost: object, paths: torch.Tensor, terms: dict[str, torch.Tensor],
                dts: torch.Tensor | None = None) -> tuple[torch.Tensor, list[float]]:
    """The goals whose path may be published this step: finite costs and free of collision.

    A goal whose cost is not finite would be chosen (``goal_choice = "human"`` took goal 0 for a NaN) or published
    (the Plan refused after the planner had adopted it); one whose path collides would be executed.

    Args:
        cost: The planner's state cost.
        paths: ``(K, T, D)`` this step's optimised trajectories.
        terms: ``smoothness``, ``obstacle``, ``human``, ``total``: ``(K,)`` their costs.
        dts: ``(K,)`` each path's waypoint spacing (s), for the warning's times; None: the warning gives fractions.

    Returns:
        ``(K,)`` bool, and each path's penetration (m, :func:`path_penetration`; NaN for a non-finite path). When
        no finite path is free, every finite one (penetration reported 0: none is set apart), with a warning.

    Raises:
        PlannerError: No goal has a finite cost; the last plan stands.
    """
    finite = torch.stack([torch.isfinite(terms[n]) for n in ("smoothness", "obstacle", "human", "total")]).all(0)
    if not bool(finite.any()):
        raise PlannerError(f"no goal has a finite cost this step (total {terms['total'].tolist()}); the last plan "
                           "stands")
    depth = path_penetration(cost, paths).tolist()
    free = finite & torch.tensor([p == 0 for p in depth], device=finite.device)
    if not bool(free.any()):  # none free: published as STOMP left them, said (see the module's docstring)
        least = min((i for i, f in enumerate(finite.tolist()) if f), key=lambda i: depth[i])
        now = time.monotonic()
        if now - _said[0] >= 1.0:  # where it starts: beyond what the robot follows before the next plan, as a rule
            at, n = first_contact(cost, paths[least]), paths.shape[1] - 1
            where = (f"{at:.0%} of the way" if dts is None else
                     f"{at * n * float(dts[least]):.2f} s into its {n * float(dts[least]):.2f} s")
            log.warning("planner: every path passes into the scene or the robot this step (the least by %.1f cm, from "
                        "%s); published as optimised: the robot follows a plan only until the next, which goes on "
                        "from it", depth[least] * 100, where)
            _said[0] = now
        return finite, [0.0 if f else p for p, f in zip(depth, finite.tolist(), strict=True)]
    return free, depth


_said = [-math.inf]
"""When the last warning of a step whose every path collides was logged (a line a second at most)."""


def invalid_reason(depth: float) -> str:
    """Why a goal the planner could reach is invalid this step, from its path's penetration (m)."""
    if depth > 0:
        return f"its path passes {depth * 100:.1f} cm into the scene or the robot this step"
    return "its cost is not finite this step"
