"""STOMP (Kalakrishnan et al., ICRA 2011) in torch, batched over K goals.

The optimizer sees only a per-waypoint cost callable and the joint bounds. One iteration, for all K
trajectories at once (tensors ``(K, R, T, D)``: goals x rollouts x waypoints x joints):

1. noisy rollouts ``theta + eps_r``, ``eps ~ N(0, sigma^2 R^-1 / max(R^-1))`` (``R = A^T A``, A the finite
   differencing matrix of accelerations; unit variance at the middle waypoint), clamped to the joint limits; with
   ``reuse`` the previous iteration's best rollouts join them with the costs they already have;
2. costs ``S(r, i)`` per rollout and waypoint (cost-to-go by default);
3. probabilities ``P(r, i) = softmax_r(-h (S - min_r S) / (max_r S - min_r S))``;
4. update ``delta = M sum_r P(r, i) eps_r(i)``, ``M`` = R^-1 with each column scaled so its max is 1/N;
   ``theta <- clamp(theta + delta)``.

Start and goal waypoints stay fixed; the best trajectory seen so far is kept per goal. The loop has
no host synchronisation (no ``.item()``, no data-dependent branching), so it runs unchanged on cuda.
Each goal draws its exploration noise from its own ``torch.Generator`` seeded per goal, so a batch of
K goals gives the same result as K separate runs with the same seeds.

Step 1 and steps 2-4 after the cost call are pure tensor functions (:func:`rollouts`, :func:`update`, and with
``reuse`` :func:`join_kept`, which joins the kept rollouts and keeps the best). After each cost call STOMP runs
:func:`advance`: those steps and the next iteration's rollouts, in that order, as one function; with
``StompConfig.compile`` it is one ``torch.compile``-d graph (about 30 small eager ops per iteration become one
call: on a CPU, where an eager op costs 5-20 us and a compiled call tens of us before any work, that is most of
what an iteration spends outside the cost). Compiled and eager give the same numbers to float rounding (tested).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch

from .compiling import compile_every_shape
from .config import StompConfig, StompError
from .stomp_steps import (
    advance,
    finite,
    finite_difference_matrix,
    join_kept,
    keep_best,
    rollouts,
    update,
    with_ends,
)

__all__ = ["StompConfig", "StompError", "StompResult", "Stomp", "finite_difference_matrix", "CostFn", "rollouts",
           "update", "join_kept", "with_ends", "finite", "keep_best"]

log = logging.getLogger("foresight.planner")

CostFn = Callable[[torch.Tensor], torch.Tensor]
"""Per-waypoint cost: ``q (K, R, T, D) -> (K, R, T)``."""


@dataclass
class StompResult:
    """Output of :meth:`Stomp.optimize`.

    Attributes:
        trajectories: ``(K, T, D)`` the least-cost trajectory seen per goal (within the bounds).
        cost: ``(K,)`` its total cost (sum over waypoints of the cost callable).
        history: ``(I' + 1, K)`` total cost of the current (noise-free) trajectory before each of the
            I' iterations run (``config.iterations``, fewer when interrupted) and after the last one.
    """

    trajectories: torch.Tensor
    cost: torch.Tensor
    history: torch.Tensor


_COMPILED: dict[str, Callable[..., tuple[torch.Tensor, ...]]] = {}
_STEPS: dict[str, Callable[..., tuple[torch.Tensor, ...]]] = {"rollouts": rollouts, "advance": advance}


def _dense(t: torch.Tensor) -> torch.Tensor:
    """``t`` with the strides of a new tensor of its shape (a copy).

    Dynamo guards every stride, those of size-1 axes too, and ``contiguous()`` leaves a view whose only uneven
    stride is a size-1 axis's as it is: with one goal (K = 1) the start sliced from the 40-waypoint path had
    another stride than the warm-up's, and the first real step compiled STOMP's steps again (0.4-0.6 s of a
    real-time run's first plan).
    """
    return t.clone(memory_format=torch.contiguous_format)


def _compiled(name: str) -> Callable[..., tuple[torch.Tensor, ...]]:
    """``torch.compile`` of :func:`rollouts` or :func:`advance`, made once per process.

    One code object each, one graph per (K, R, T, D, dtype) seen, up to
    :data:`~services.planner.compiling.RECOMPILE_LIMIT` of them.
    """
    if name not in _COMPILED:
        _COMPILED[name] = compile_every_shape(_STEPS[name], dynamic=False)  # past 8 graphs: eager (compiling)
    return _COMPILED[name]


class Stomp:
    """Batched STOMP optimizer over K independent trajectories.

    Args:
        config: Parameters (validated).
        bounds: ``(lower (D,), upper (D,))`` joint limits; every rollout and result is clamped into them.
    """

    def __init__(self, config: StompConfig, bounds: tuple[torch.Tensor, torch.Tensor]) -> None:
        config.validate()
        self.config = config
        self.device = torch.device(config.device)
        self.dtype = config.torch_dtype
        lower, upper = (torch.as_tensor(b, dtype=self.dtype, device=self.device).reshape(-1) for b in bounds)
        if lower.shape != upper.shape or not bool(torch.all(lower <= upper)):
            raise StompError(f"bounds must be two (D,) tensors with lower <= upper, got {lower} and {upper}")
        self.lower, self.upper = lower, upper
        self.dof = int(lower.shape[0])
        if config.joint_noise_scale and len(config.joint_noise_scale) != self.dof:
            raise StompError(f"stomp.joint_noise_scale has {len(config.joint_noise_scale)} values for "
                             f"{self.dof} joints")
        scale = torch.tensor(config.joint_noise_scale or [1.0] * self.dof, dtype=self.dtype, device=self.device)
        self.joint_std = config.noise_std * scale  # (D,)

        n = config.waypoints - 2
        a = finite_difference_matrix(n)
        r = a.T @ a  # (N, N) = A^T A, positive definite
        r_inv = torch.linalg.inv(r)
        cov = r_inv / r_inv.max()  # scaled R^-1: unit maximum variance
        m = r_inv / r_inv.max(dim=0, keepdim=True).values / n  # columns scaled to max 1/N
        self.R = r.to(self.device, self.dtype)
        self.noise_chol = torch.linalg.cholesky(cov).to(self.device, self.dtype)  # (N, N) lower
        self.M = m.to(self.device, self.dtype)  # (N, N)
        # cost-to-go as one product: S (.., N) = c (.., N + 1) @ U, waypoints 1..T-1 (the goal's cost
        # varies with the last segment), U[j, i] = 1 for j >= i
        self.to_go = torch.tril(torch.ones(n + 1, n)).contiguous().to(self.device, self.dtype)
        self._compile = bool(config.compile)

    def sample_noise(self, k: int, seeds: Sequence[int]) -> torch.Tensor:
        """Exploration noise for all iterations, drawn per goal from its own generator.

        Args:
            k: Number of goals K.
            seeds: K seeds, one per goal.

        Returns:
            ``(I, K, R, N, D)`` noise ``eps ~ N(0, diag(sigma^2) (x) scaled R^-1)`` per iteration.

        Raises:
            StompError: ``seeds`` does not hold K seeds.
        """
        c = self.config
        n = c.waypoints - 2
        if len(seeds) != k:
            raise StompError(f"got {len(seeds)} seeds for {k} goals")
        decay = c.noise_decay ** torch.arange(c.iterations, device=self.device, dtype=self.dtype)
        std = self.joint_std * decay[:, None, None]  # (I, 1, D)
        eps = torch.empty((c.iterations, k, c.rollouts, n, self.dof), device=self.device, dtype=self.dtype)
        for i, s in enumerate(seeds):  # one goal at a time: its (N, I*R*D) block stays in cache
            g = torch.Generator(device=self.device)
            g.manual_seed(int(s))
            z = torch.randn((n, c.iterations, c.rollouts, self.dof), generator=g, device=self.device, dtype=self.dtype)
            # L z as one (N, N) x (N, I*R*D) product: correlated along the waypoints, independent elsewhere
            eps[:, i] = ((self.noise_chol @ z.view(n, -1)).view(z.shape) * std).permute(1, 2, 0, 3)
        return eps

    def _check(self, q0: torch.Tensor) -> torch.Tensor:
        c = self.config
        q0 = torch.as_tensor(q0, device=self.device, dtype=self.dtype)
        if q0.ndim != 3 or q0.shape[1] != c.waypoints or q0.shape[2] != self.dof:
            raise StompError(f"initial trajectories must have shape (K, {c.waypoints}, {self.dof}), "
                             f"got {tuple(q0.shape)}")
        if not bool(torch.isfinite(q0).all()):
            raise StompError("initial trajectories contain NaN or inf")
        tol = 1e-5 if self.dtype == torch.float32 else 1e-9
        ends = q0[:, [0, -1]]
        if bool(((ends < self.lower - tol) | (ends > self.upper + tol)).any()):
            raise StompError("start or goal configuration outside the joint limits")
        return torch.clamp(q0, self.lower, self.upper)

    def optimize(self, q0: torch.Tensor, cost_fn: CostFn, seeds: Sequence[int] | None = None,
                 interrupt: Callable[[], bool] | None = None, min_iterations: int = 0) -> StompResult:
        """Run ``config.iterations`` STOMP iterations on K trajectories at once (fewer when interrupted).

        Args:
            q0: ``(K, T, D)`` initial trajectories; ``q0[:, 0]`` and ``q0[:, -1]`` (start and goal)
                stay fixed and must lie within the bounds; interior waypoints are clamped into them.
            cost_fn: ``q (K, R', T, D) -> (K, R', T)`` per-waypoint cost, called once per iteration
                with R' = R + 1 (the current trajectory first, then the R noisy rollouts; with ``reuse``,
                R - reuse + 1 after the first iteration) and once at the end with R' = 1. Goals must not
                interact (row k depends only on ``q[k]``).
            seeds: K noise seeds (default ``config.seed + k``).
            interrupt: Anytime: asked after each iteration from ``min_iterations`` on; True stops the
                loop there (the result is the best so far). A host-side callable (e.g. "is a newer input
                waiting?"): it never reads a tensor, so it adds no device synchronisation.
            min_iterations: Iterations always run before ``interrupt`` is asked.

        Returns:
            The least-cost trajectory per goal, its cost and the cost history.

        Raises:
            StompError: If ``q0`` has the wrong shape, is not finite, or its endpoints violate the bounds.
        """
        c = self.config
        q0 = self._check(q0)
        k = q0.shape[0]
        if seeds is None:
            seeds = [c.seed + i for i in range(k)]
        noise = self.sample_noise(k, seeds)  # (I, K, R, N, D); raises on a wrong number of seeds
        start, goal = _dense(q0[:, :1]), _dense(q0[:, -1:])  # (K, 1, D)
        theta = _dense(q0[:, 1:-1])  # (K, N, D) the free waypoints (one compiled layout)
        best_theta = theta.clone()  # never the same tensor as theta: one compiled graph (dynamo guards aliasing)
        best_cost = torch.full((k,), math.inf, device=self.device, dtype=self.dtype)
        history = []

        to_go = self.to_go if c.cost_to_go else None
        fresh = c.rollouts - c.reuse  # new rollouts per iteration after the first (all of them without reuse)
        kept: tuple[torch.Tensor | None, torch.Tensor | None] = (None, None)  # reused rollouts and their costs
        # 1. noisy rollouts, clamped to the joint limits (eps is the noise actually applied); the first iteration's
        # here, every later one's with the update before it (advance)
        q, eps = self._first_rollouts(theta, noise[0], start, goal)
        for it in range(c.iterations):
            # 2. costs of the current trajectory (rollout 0) and of the new noisy rollouts (with reuse: and the
            # previous iteration's best rollouts, with the costs they have; the best of them all are kept)
            cost = self._cost(cost_fn, q, k, q.shape[1])
            # 2-4. keep the best, probabilities per waypoint, smoothed update within the limits; and 1. of the next
            # iteration (after the last, its noise again: rollouts nobody costs)
            nxt = _dense(noise[min(it + 1, c.iterations - 1), :, :fresh])
            theta, total, best_cost, best_theta, *kept, q, eps = self._step(
                "advance", theta, eps, cost, *kept, c.reuse, best_cost, best_theta, self.lower, self.upper, self.M,
                to_go, c.sensitivity, nxt, start, goal)
            history.append(total)
            if interrupt is not None and it + 1 >= min_iterations and it + 1 < c.iterations and interrupt():
                break

        total = finite(self._cost(cost_fn, with_ends(theta[:, None], start, goal), k, 1))[:, 0].sum(-1)
        history.append(total)
        better = total < best_cost
        best_cost = torch.where(better, total, best_cost)
        best_theta = torch.where(better[:, None, None], theta, best_theta)
        traj = torch.cat([start, best_theta, goal], 1)
        return StompResult(traj, best_cost, torch.stack(history))

    @property
    def compiled(self) -> bool:
        """Whether the rollout and update steps go through ``torch.compile`` (``config.compile``, no fallback so far).

        A shape beyond torch's recompile limit runs eagerly inside the compiled wrapper without changing this.
        """
        return self._compile

    def warm_up(self, k: int) -> None:
        """With ``config.compile``: compile the rollout and update steps for K goals now (not in the first step)."""
        if not self._compile or k < 1:  # no goal to plan for: nothing to compile
            return
        c, n = self.config, self.config.waypoints - 2
        fresh = c.rollouts - c.reuse
        theta = _dense(((self.lower + self.upper) / 2).expand(k, n, self.dof))
        start, goal = _dense(theta[:, :1]), _dense(theta[:, :1])
        # distinct tensors as in optimize: dynamo guards aliasing between arguments (an aliased call is another graph)
        q, eps = self._first_rollouts(theta, torch.zeros(k, c.rollouts, n, self.dof, device=self.device,
                                                         dtype=self.dtype), start, goal)
        cost = torch.zeros(q.shape[:3], device=self.device, dtype=self.dtype)
        best = torch.full((k,), math.inf, device=self.device, dtype=self.dtype)
        nxt = torch.zeros(k, fresh, n, self.dof, device=self.device, dtype=self.dtype)
        to_go = self.to_go if c.cost_to_go else None
        # the first iteration (nothing kept yet), then, with reuse, the others (R - reuse new rollouts)
        theta, _, best, best_theta, kept_q, kept_cost, _, eps = self._step(
            "advance", theta, eps, cost, None, None, c.reuse, best, theta.clone(), self.lower, self.upper, self.M,
            to_go, c.sensitivity, nxt, start, goal)
        if c.reuse:
            self._step("advance", theta, eps, _dense(cost[:, :fresh + 1]), kept_q, kept_cost, c.reuse, best,
                       best_theta, self.lower, self.upper, self.M, to_go, c.sensitivity, nxt.clone(), start, goal)

    def _first_rollouts(self, theta: torch.Tensor, noise: torch.Tensor, start: torch.Tensor,
                        goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Step 1 of the first iteration: ``noise`` ``(K, R, N, D)``; with reuse, as the two shapes of the loop.

        With reuse the later iterations make R - reuse new rollouts, the first all R: as two calls of those
        two shapes (R - reuse and reuse), so that no third graph is compiled for R.
        """
        fresh = self.config.rollouts - self.config.reuse
        q, eps = self._step("rollouts", theta, _dense(noise[:, :fresh]), start, goal, self.lower, self.upper)
        if self.config.reuse:
            q2, eps2 = self._step("rollouts", theta, _dense(noise[:, fresh:]), start, goal, self.lower,
                                  self.upper)
            q, eps = torch.cat([q, q2[:, 1:]], 1), torch.cat([eps, eps2], 1)
        return q, eps

    def _step(self, name: str, *args: object) -> tuple[torch.Tensor, ...]:
        """One of the steps (:data:`_STEPS`), compiled with ``config.compile`` (eager if compiling fails)."""
        if self._compile:
            try:
                return _compiled(name)(*args)
            except Exception as exc:  # no C++ compiler, unsupported backend...: the same function, eager
                log.warning("torch.compile of STOMP's %s step failed (%s: %s); running it eagerly", name,
                            type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")
                self._compile = False
        return _STEPS[name](*args)

    def _cost(self, cost_fn: CostFn, q: torch.Tensor, k: int, r: int) -> torch.Tensor:
        cost = cost_fn(q)
        if tuple(cost.shape) != (k, r, self.config.waypoints):
            raise StompError(f"cost callable returned shape {tuple(cost.shape)}, expected "
                             f"{(k, r, self.config.waypoints)}")
        return cost.to(self.dtype)
