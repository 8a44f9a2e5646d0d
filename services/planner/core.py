"""Pure multi-goal planner (Algorithm 1 of Mainprice & Berenson, IROS 2013); no Zenoh in here.

:class:`Planner` holds the robot model, the goal configurations, the state cost (obstacle signed
distance + predicted human occupancy) and a batched :class:`~services.planner.stomp.Stomp`. Each
:meth:`Planner.step` is one replanning step:

1. validate the robot configuration and the occupancy grid (``PlannerInputError`` naming the problem);
2. set the predicted occupancy X in the cost (predictVoxelOccupancy happens in the predictor);
3. ``q_t``: where the robot will be when this plan starts, i.e. ``lookahead_s`` further along the
   previous tau_best from the robot's projection onto it (or the robot's configuration itself on the
   first step or when it has left tau_best);
4. reconnectPrevious for every goal (initStraightLines on the first step);
5. STOMP for all valid goals in one batch (``stomp.iterations`` iterations);
6. getBestTrajectory: the least total cost (smoothness + obstacle + human) among valid goals.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from shared.scene import Grid, Scene

from .config import PlannerConfig
from .costs import acceleration_cost, path_dt, waypoint_times
from .fused import FusedCost, supports
from .inputs import PlannerError, PlannerInputError, check_configuration, check_lookahead, check_occupancy
from .multigoal import best, choice_key, init_straight_lines, interpolate_path, project_onto_path, reconnect_previous
from .protocols import PlannerCost, PlannerGoals, PlannerRobot
from .result import PlanResult
from .stomp import Stomp
from .validity import invalid_reason, publishable

__all__ = ["PlannerConfig", "PlannerError", "PlannerInputError", "GoalSet", "PlanResult", "Planner", "goals_per_call"]

log = logging.getLogger("foresight.planner")


@dataclass
class GoalSet:
    """The K goals planned for.

    Attributes:
        names: K goal names (e.g. cup names).
        q: ``(K, D)`` goal configurations (within the joint limits; arbitrary where invalid).
        valid: ``(K,)`` bool, goals that can be planned for.
        reasons: K strings, why a goal is invalid ("" when valid).
    """

    names: list[str]
    q: torch.Tensor
    valid: torch.Tensor
    reasons: list[str] = field(default_factory=list)

    @classmethod
    def joint_space(cls, names: Sequence[str], q: Any, robot: Any) -> GoalSet:
        """Goals given directly as configurations ``q`` ``(K, D)``; those outside the limits are invalid."""
        q = torch.as_tensor(np.asarray(q, dtype=np.float64), device=robot.lower.device, dtype=robot.lower.dtype)
        if q.ndim != 2 or q.shape[1] != robot.lower.shape[0] or len(names) != q.shape[0]:
            raise PlannerError(f"joint-space goals must be (K, {robot.lower.shape[0]}) with K names, "
                               f"got {tuple(q.shape)} and {len(names)} names")
        finite = torch.isfinite(q).all(-1)
        inside = ((q >= robot.lower - 1e-6) & (q <= robot.upper + 1e-6)).all(-1) & finite
        reasons = ["" if bool(ok) else "goal configuration outside the joint limits" for ok in inside]
        q = torch.where(finite[:, None], q, robot.lower.expand_as(q))
        return cls(list(names), torch.maximum(torch.minimum(q, robot.upper), robot.lower), inside, reasons)


class Planner:
    """Multi-goal STOMP planner over a scene (Algorithm 1).

    Args:
        scene: The scene (robot placement, obstacles, cups, grid).
        config: Planner settings.
        robot: A :class:`~services.planner.protocols.PlannerRobot` (default: ``PR2.from_scene``).
        cost: A :class:`~services.planner.protocols.PlannerCost`, ``q (K, R, T, D) -> (K, R, T, 2)``
            (obstacle, human) with ``set_occupancy`` (default: the PR2 ``StateCost`` of the scene).
        goals: A :class:`~services.planner.protocols.PlannerGoals` (a :class:`GoalSet`, or by default the
            ``IKGoals`` of a pre-grasp at each cup of ``config.goals``).
        w_smooth: Weight of the squared accelerations (default: ``config.cost.w_smooth``).

    Raises:
        PlannerError: If no goal is valid.
    """

    def __init__(self, scene: Scene, config: PlannerConfig | None = None, *, robot: PlannerRobot | None = None,
                 cost: PlannerCost | None = None, goals: PlannerGoals | None = None,
                 w_smooth: float | None = None) -> None:
        self.config = config or PlannerConfig()
        self.config.validate()
        c = self.config
        if c.threads:
            torch.set_num_threads(c.threads)
        self.scene = scene
        self.device = torch.device(c.device)
        self.dtype = torch.float32 if c.dtype == "float32" else torch.float64
        if robot is None:
            from shared.robot import PR2

            robot = PR2.from_scene(scene, device=self.device, dtype=self.dtype)
        self.robot: PlannerRobot = robot
        if cost is None:
            cost = _default_cost(scene, robot, c)
        self.cost: PlannerCost = cost
        self.w_smooth = float(c.cost.w_smooth if w_smooth is None else w_smooth)
        if goals is None:
            goals = _default_goals(scene, robot, cost, c)
        if not bool(goals.valid.any()):
            raise PlannerError("no reachable goal: " + ("; ".join(f"{n}: {r}" for n, r in zip(
                goals.names, goals.reasons, strict=False)) or f"the scene has no cups ({scene.name}) to plan for"))
        self.goals: PlannerGoals = goals
        for name, reason in zip(goals.names, goals.reasons, strict=False):
            if reason:
                log.warning("goal %s dropped: %s", name, reason)
        self.lower, self.upper = robot.lower.to(self.device, self.dtype), robot.upper.to(self.device, self.dtype)
        self._vmax = robot.velocity_limits.to(self.device, self.dtype) * c.velocity_scale  # (D,)
        self._inv_vmax = 1.0 / self._vmax
        vel = robot.velocity_limits.double().cpu()
        self.stomp = Stomp(c.stomp_config((vel / vel.max()).tolist()), (self.lower, self.upper))
        self.valid_index = torch.nonzero(goals.valid.cpu()).flatten().tolist()
        self.goal_q = goals.q.to(self.device, self.dtype)[self.valid_index]  # (Kv, D)
        self.fused: FusedCost | None = None
        if c.fused_cost and supports(robot, cost):
            self.fused = FusedCost(robot, cost, self.w_smooth, self._vmax, c.integrate_costs, compile=c.compile,
                                   grid=scene.grid, dwell=c.goal_dwell_s)
            per_call = goals_per_call(len(self.valid_index), c.cost_chunk_goals if self.device.type == "cpu" else 0)
            # with reuse, every iteration after the first costs its new rollouts and theta only (the first: two calls)
            self.fused.warm_up(per_call * (c.stomp.rollouts - c.stomp.reuse + 1), c.stomp.waypoints)
        self.stomp.warm_up(len(self.valid_index))
        self.step_index = 0
        self._prev: torch.Tensor | None = None  # (Kv, T, D) previous optimised trajectories
        self._prev_best: int | None = None  # index into the valid goals
        self._prev_dt = 1.0
        self._occupancy_set = False

    # ------------------------------------------------------------------------------------------
    # costs

    def waypoint_time(self, q: torch.Tensor) -> torch.Tensor:
        """Time each waypoint stands for when the path is executed (:func:`~.costs.waypoint_times`).

        Args:
            q: ``(..., T, D)`` trajectories.

        Returns:
            ``(..., T)`` seconds: the path's one ``dt`` (its slowest segment at the scaled velocity limits, what
            the plan carries and the executor runs; without the plan's ``min_dt`` floor), half of it at both ends. With
            ``integrate_costs`` the state costs are weighted by it, so they integrate over the time the robot
            spends along the path (a detour or a loop costs more), instead of counting waypoints
            (:meth:`waypoint_cost` adds the goal's dwell).
        """
        return waypoint_times(q, self._inv_vmax)

    def _state_terms(self, q: torch.Tensor) -> torch.Tensor:
        """``(K, R, T, D)`` -> ``(K, R, T, 2)`` obstacle and human terms, time-weighted if configured.

        With ``integrate_costs`` the human term's last waypoint also counts ``goal_dwell_s`` (the robot stays
        at its goal: holding still inside the human's volume is not free).
        """
        terms = self.cost(q)
        if self.config.integrate_costs:
            dt = self.waypoint_time(q)[..., None].expand_as(terms).clone()
            dt[..., -1, 1] += self.config.goal_dwell_s  # the human term at the goal: the time staying there
            terms = terms * dt
        return terms

    def waypoint_cost(self, q: torch.Tensor) -> torch.Tensor:
        """Total cost per waypoint, the callable STOMP optimises.

        The fused kernel (:class:`~services.planner.fused.FusedCost`, ``fused_cost``) when the robot and
        cost support it, else :meth:`waypoint_cost_reference`; the two are tested equal.

        Args:
            q: ``(K, R, T, D)`` trajectories.

        Returns:
            ``(K, R, T)``: ``w_smooth`` x squared acceleration + obstacle + human terms (the latter two
            times :meth:`waypoint_time` when ``integrate_costs``, the human term at the goal plus
            ``goal_dwell_s``).
        """
        if self.fused is not None:
            return self.fused(q)
        return self.waypoint_cost_reference(q)

    def waypoint_cost_reference(self, q: torch.Tensor) -> torch.Tensor:
        """:meth:`waypoint_cost` from the state cost callable (``(K, R, T, D) -> (K, R, T)``), unfused."""
        return self._state_terms(q).sum(-1) + self.w_smooth * acceleration_cost(q)

    def cost_terms(self, q: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-trajectory cost terms.

        Args:
            q: ``(K, T, D)`` trajectories.

        Returns:
            ``{"smoothness", "obstacle", "human", "total"}`` -> ``(K,)`` each.
        """
        if self.fused is not None:
            smooth, obstacle, human = self.fused.terms(q).sum(-1)  # (K,) each
            out = {"smoothness": smooth, "obstacle": obstacle, "human": human}
        else:
            terms = self._state_terms(q[:, None])[:, 0].sum(1)  # (K, 2)
            smooth = self.w_smooth * acceleration_cost(q).sum(-1)
            out = {"smoothness": smooth, "obstacle": terms[:, 0], "human": terms[:, 1]}
        out["total"] = out["smoothness"] + out["obstacle"] + out["human"]
        return out

    # ------------------------------------------------------------------------------------------
    # input checks (services.planner.inputs)

    def check_configuration(self, q: Any) -> torch.Tensor:
        """A robot configuration ``(D,)`` checked (:func:`~services.planner.inputs.check_configuration`).

        Returns:
            ``(D,)`` tensor on the planner's device, clamped into the limits.
        """
        lo, hi = self.lower.double().cpu().numpy(), self.upper.double().cpu().numpy()
        names = getattr(self.robot, "joint_names", None)
        arr = check_configuration(q, lo, hi, self.config.limit_tol, names)
        return torch.as_tensor(arr, device=self.device, dtype=self.dtype)

    def check_occupancy(self, occupancy: Any, grid: Grid | None = None) -> tuple[torch.Tensor, np.ndarray, float]:
        """An occupancy grid checked (:func:`~services.planner.inputs.check_occupancy`).

        Args:
            occupancy: An ``OccupancyGrid`` message or a dense ``(nx, ny, nz)`` array.
            grid: Geometry of a dense array (default: the scene's grid).

        Returns:
            ``(occ (nx, ny, nz) tensor, origin (3,), resolution)``.
        """
        dense, origin, res = check_occupancy(occupancy, grid or self.scene.grid)
        return torch.as_tensor(dense, device=self.device, dtype=self.dtype), origin, res

    # ------------------------------------------------------------------------------------------
    # Algorithm 1

    def reset(self, seed: int | None = None) -> None:
        """Forget the previous trajectories (next step starts from straight lines).

        Args:
            seed: New base seed of STOMP's exploration noise (default: keep ``config.seed``).
        """
        if seed is not None:
            self.config = dataclasses.replace(self.config, seed=int(seed))
        self._prev, self._prev_best, self.step_index = None, None, 0

    def _seeds(self) -> list[int]:
        ss = np.random.SeedSequence([self.config.seed, self.step_index])
        return [int(x) for x in ss.generate_state(len(self.goals.names))[self.valid_index]]

    def _dt(self, traj: torch.Tensor) -> torch.Tensor:
        """``(K, T, D)`` -> ``(K,)`` seconds per waypoint so no joint exceeds its scaled velocity limit."""
        return path_dt(traj, self._inv_vmax, self.config.min_dt)

    def start_configuration(self, q_current: torch.Tensor, lookahead_s: float | None = None
                            ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """``q_t``: where the robot will be when the new plan starts, and its index on tau_best.

        Args:
            q_current: ``(D,)`` the robot's configuration now.
            lookahead_s: Time until the plan is executed (default ``config.lookahead_s``).

        Returns:
            ``(q_t (D,), s_t)``: ``s_t`` is the fractional waypoint index on the previous tau_best, or
            None on the first step or when the robot is farther than ``off_path_tol`` from tau_best.
        """
        if self._prev is None or self._prev_best is None:
            return q_current, None
        tau = self._prev[self._prev_best]
        s_cur, dist = project_onto_path(tau, q_current)
        if float(dist) > self.config.off_path_tol:
            log.debug("robot %.3f from tau_best: reconnecting every goal from its configuration", float(dist))
            return q_current, None
        ahead = check_lookahead(self.config.lookahead_s if lookahead_s is None else lookahead_s)
        s_t = (s_cur + ahead / self._prev_dt).clamp(max=tau.shape[0] - 1)
        return interpolate_path(tau, s_t), s_t

    def departure(self, q_current: Any) -> float | None:
        """Distance (rad, the norm of :func:`project_onto_path`) of ``q_current`` ``(D,)`` from tau_best; None at first.

        Beyond ``off_path_tol`` the robot has left the plan (the real-time service replans at once). Clamped into the
        limits as a step's start is (unclamped, a state just past one left its own plan: 59 steps in 3 s, a review).
        """
        if self._prev is None or self._prev_best is None:
            return None
        q = torch.as_tensor(np.asarray(q_current, dtype=np.float64), device=self.device, dtype=self.dtype)
        return float(project_onto_path(self._prev[self._prev_best], q.clamp(self.lower, self.upper))[1])

    def step(self, q_current: Any, occupancy: Any, grid: Grid | None = None,
             interrupt: Callable[[], bool] | None = None, lookahead_s: float | None = None) -> PlanResult:
        """One replanning step of Algorithm 1.

        Args:
            q_current: ``(D,)`` the robot's configuration.
            occupancy: Predicted occupancy: an ``OccupancyGrid`` message or a dense ``(nx, ny, nz)``
                array of probabilities on ``grid``.
            grid: Geometry of a dense ``occupancy`` (default: the scene's grid).
            interrupt: Anytime: STOMP stops early when this returns True, after at least
                ``anytime_min_iterations`` iterations (ignored while that is 0).
            lookahead_s: Time until the plan will be executed (default ``config.lookahead_s``).

        Returns:
            The K trajectories, their cost terms and the chosen goal.

        Raises:
            PlannerInputError: Malformed input; the planner's state is left unchanged.
        """
        t0 = time.perf_counter()
        q = self.check_configuration(q_current)
        occ, origin, res = self.check_occupancy(occupancy, grid)
        self.cost.set_occupancy(occ, origin, res)
        c = self.config
        q_t, s_t = self.start_configuration(q, lookahead_s)
        off_path = self._prev is not None and s_t is None
        if self._prev is None:
            init = init_straight_lines(q_t, self.goal_q, c.stomp.waypoints)
        else:
            init = reconnect_previous(self._prev, self._prev_best, q_t, s_t, self.waypoint_cost)
        anytime = interrupt if c.anytime_min_iterations > 0 else None
        result = self.stomp.optimize(init, self.waypoint_cost, seeds=self._seeds(), interrupt=anytime,
                                     min_iterations=c.anytime_min_iterations)
        # a reached goal holds still: q_t (waypoint 0, where the robot is), then the goal; STOMP would trade a tiny
        reached = (init[:, -1] - init[:, 0]).norm(dim=-1) <= c.goal_tol  # cost at it for a loop away and back
        trajs = torch.where(reached[:, None, None], torch.cat([init[:, :1], init[:, -1:].expand_as(init[:, 1:])], 1),
                            result.trajectories)  # (Kv, T, D)
        terms = self.cost_terms(trajs)
        # a goal whose cost is not finite (chosen or published, it would derail the next steps), or whose path goes
        dts = self._dt(trajs)
        valid, depth = publishable(self.cost if c.free_paths else None, trajs, terms, dts)  # into the scene or robot
        chosen_v = best(choice_key(terms, c.goal_choice, valid), valid)
        self._prev, self._prev_best, self._prev_dt = trajs, chosen_v, float(dts[chosen_v])

        k = len(self.goals.names)
        ok = [i for i, v in zip(self.valid_index, valid.tolist(), strict=True) if v]  # the goals valid this step
        out_traj = q_t.expand(k, c.stomp.waypoints, -1).clone()
        out_traj[ok] = trajs[valid]
        costs = {name: np.full(k, np.inf) for name in ("smoothness", "obstacle", "human", "total")}
        for name in costs:
            costs[name][ok] = terms[name][valid].double().cpu().numpy()
        out_valid = np.zeros(k, dtype=bool)
        out_valid[ok] = True
        reasons = list(self.goals.reasons) or [""] * k
        for i in sorted(set(self.valid_index) - set(ok)):
            reasons[i] = invalid_reason(depth[self.valid_index.index(i)])
            log.warning("planner: goal %s, step %d: %s", self.goals.names[i], self.step_index, reasons[i])
        result_step = self.step_index
        self.step_index += 1
        return PlanResult(
            step=result_step, goal_names=list(self.goals.names), joint_names=list(self.robot.joint_names),
            trajectories=out_traj.float().cpu().numpy(), cost_smoothness=costs["smoothness"],
            cost_obstacle=costs["obstacle"], cost_human=costs["human"], cost_total=costs["total"],
            valid=out_valid, chosen=self.valid_index[chosen_v],
            dt=self._prev_dt, start=q_t.double().cpu().numpy(), planning_ms=(time.perf_counter() - t0) * 1e3,
            reasons=reasons, iterations=result.history.shape[0] - 1,
            cost_history=result.history.double().cpu().numpy(), off_path=off_path)


def goals_per_call(k: int, limit: int) -> int:
    """Goals whose rollouts share one fused-cost call (``PlannerConfig.cost_chunk_goals``).

    On a CPU a call over a few goals keeps the compiled kernel's intermediates in cache (K = 16: 315 -> 269 ms
    per step, docs/planner.md). Goals are never split across calls: the largest divisor of ``k`` in
    ``[ceil(limit / 2), limit]``; without one (K = 5, 7, 11, ...: 1-goal calls measured 13-15 % slower) one call.

    Args:
        k: Valid goals K.
        limit: ``cost_chunk_goals`` (0: one call).

    Returns:
        Goals per call (a divisor of ``k``; 1 when ``k`` is 0).
    """
    if limit <= 0 or k <= limit:
        return max(k, 1)
    return max((d for d in range(-(-limit // 2), limit + 1) if k % d == 0), default=k)


def _default_cost(scene: Scene, robot: Any, config: PlannerConfig) -> PlannerCost:
    """The PR2's :class:`~services.planner.costs.StateCost` of the scene with ``config.cost``."""
    from .costs import StateCost

    return StateCost.from_scene(scene, robot, config.cost)


def _default_goals(scene: Scene, robot: Any, cost: Any, config: PlannerConfig) -> PlannerGoals:
    """A pre-grasp goal at each cup of ``config.goals`` (default: every cup) by IK (``goals.cup_goals``)."""
    from .goals import cup_goals

    return cup_goals(scene, robot, cost, names=config.goals or None)
