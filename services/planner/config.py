"""The ``[planner]`` config tree: the service's options, the planner's, STOMP's and the costs'.

One dataclass per component, held by what it configures::

    PlannerServiceConfig            [planner]          mode, period_s, ... (how the service runs it)
      planner: PlannerConfig        [planner] (inline) device, goals, timing, ...
        stomp: StompConfig          [planner.stomp]    --stomp.iterations, FORESIGHT_PLANNER_STOMP_ITERATIONS
        cost: CostConfig            [planner.cost]     --cost.w-human, FORESIGHT_PLANNER_COST_W_HUMAN

STOMP's ``seed``, ``device`` and ``dtype`` are the planner's (hidden in ``[planner.stomp]``); see
:mod:`shared.config` for how file, environment and flags reach every field.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from shared.config import LOG_LEVELS, ConfigError, nested, opt
from shared.devices import check_device
from shared.protocol.limits import JOINT_LIMIT_TOL, MAX_DT_S, MAX_WAYPOINTS, MIN_DT_S
from shared.scene import SCENE_HELP

from .replan import TRIGGERS

if TYPE_CHECKING:
    import torch

__all__ = ["PlannerConfig", "PlannerServiceConfig", "StompConfig", "StompError", "CostConfig", "MAX_ROLLOUTS",
           "MAX_THREADS", "MIN_TORSO_TABLE_STEP_M", "SDF_RESOLUTION_M"]

MAX_ROLLOUTS = 1024
"""Most noisy rollouts per goal and iteration: 100 times the default; the rollouts' tensors grow with it."""

SDF_RESOLUTION_M = (0.005, 0.5)
"""Bounds of ``cost.sdf_resolution``, those of ``foresight train --resolution``: 1e-300 was a numpy traceback (a grid
of negative size), 0.005 m is 64 times the default's voxels."""

MIN_TORSO_TABLE_STEP_M = 1e-4
"""Smallest ``cost.torso_table_step`` but 0 (off): about 3,000 rows over the PR2's lift; 1e-300 was a torch
traceback (a table of 10^299 rows)."""

MAX_THREADS = 1024
"""Most torch threads: 3000000000 was a ValueError traceback from ``torch.set_num_threads``."""


class StompError(ValueError):
    """Bad input to STOMP (shape, non-finite values, start/goal outside the bounds); names the problem."""


@dataclass
class StompConfig:
    """Parameters of :class:`Stomp`.

    Attributes:
        rollouts: Noisy rollouts R per goal and iteration.
        waypoints: Waypoints T per trajectory (start and goal included).
        iterations: Iterations per call of :meth:`Stomp.optimize` (one replanning step), at least 1.
        noise_std: Exploration noise standard deviation (rad) at the middle of the trajectory (the
            scaled R^-1 has unit maximum variance).
        joint_noise_scale: Optional per-joint factors (length D) on ``noise_std``; empty = all 1.
        noise_decay: Noise multiplied by this factor after every iteration (1 = constant).
        sensitivity: h, the exponent scale of the per-timestep probabilities (paper: 10).
        cost_to_go: Rank rollouts per waypoint by their cost-to-go (sum of costs from that waypoint
            to the goal, as in PI^2) rather than the waypoint's own cost.
        reuse: Rollouts of the previous iteration kept in the next one, least total cost first, with the
            costs they already have (ros-industrial STOMP and the paper authors' code: 5 of 10): each
            iteration after the first then costs ``rollouts - reuse`` new rollouts and the current trajectory
            (10 and 5 since they were measured against 16 and 0: docs/planner.md, "Reused rollouts").
        seed: Base seed; goal k uses ``seed + k`` unless seeds are given to :meth:`Stomp.optimize`.
        device: Torch device, e.g. ``"cpu"`` or ``"cuda"``.
        dtype: ``"float32"`` or ``"float64"``.
        compile: ``torch.compile`` the rollout and update steps (eager when compilation fails).
    """

    rollouts: int = 10
    waypoints: int = 40
    iterations: int = 50
    noise_std: float = 0.1
    joint_noise_scale: list[float] = field(default_factory=list)
    noise_decay: float = 1.0
    sensitivity: float = 10.0
    cost_to_go: bool = True
    reuse: int = 5
    seed: int = 0
    device: str = "cpu"
    dtype: str = "float32"
    compile: bool = False

    def validate(self) -> None:
        """Raise :class:`StompError` naming the first bad field."""
        if not 2 <= self.rollouts <= MAX_ROLLOUTS:  # 10^12 asked torch for 2.5 PB in a traceback
            raise StompError(f"stomp.rollouts must be in [2, {MAX_ROLLOUTS}], got {self.rollouts}")
        if not 0 <= self.reuse < self.rollouts:
            raise StompError(f"stomp.reuse must be in [0, rollouts - 1 = {self.rollouts - 1}], got {self.reuse}")
        if self.waypoints < 3:
            raise StompError(f"stomp.waypoints must be >= 3, got {self.waypoints}")
        if self.iterations < 1:  # 0 was let through and failed in the first plan (an IndexError)
            raise StompError(f"stomp.iterations must be >= 1, got {self.iterations}")
        if not (self.noise_std >= 0 and math.isfinite(self.noise_std)):
            raise StompError(f"stomp.noise_std must be finite and >= 0, got {self.noise_std}")
        if any(not (s >= 0 and math.isfinite(s)) for s in self.joint_noise_scale):
            raise StompError(f"stomp.joint_noise_scale must be finite and >= 0, got {self.joint_noise_scale}")
        if not (0 < self.noise_decay <= 1):
            raise StompError(f"stomp.noise_decay must be in (0, 1], got {self.noise_decay}")
        if not (self.sensitivity > 0 and math.isfinite(self.sensitivity)):
            raise StompError(f"stomp.sensitivity must be > 0, got {self.sensitivity}")
        if self.dtype not in ("float32", "float64"):
            raise StompError(f"stomp.dtype must be float32 or float64, got {self.dtype!r}")

    @property
    def torch_dtype(self) -> torch.dtype:
        """The torch dtype named by :attr:`dtype`."""
        import torch  # here, not at the top: the config tree loads without torch (--help)

        return torch.float32 if self.dtype == "float32" else torch.float64


@dataclass
class CostConfig:
    """Weights and shape of the planning costs (held by :class:`StateCost` as ``config``)."""

    w_smooth: float = 10.0  # weight of the squared accelerations (rad^2 per waypoint step); the planner's default
    w_obstacle: float = 10.0  # weight of the obstacle penetration (m, summed over spheres)
    w_human: float = 1.0  # weight of the summed occupancy probability
    clearance: float = 0.05  # obstacle margin eps (m): spheres closer than this to a surface pay
    self_clearance: float = 0.01  # margin of the arm-vs-body self-collision term (m); < 0 disables it
    sdf_resolution: float = 0.02  # voxel edge of the static signed distance field (m; 0.005-0.5)
    human_points: int = 1  # points per sphere for the human cost: 1 (centre) or 7 (centre + 6)
    human_point_radius: float = 0.7  # offset of the extra points, as a fraction of the sphere radius
    human_interp: str = "trilinear"  # "trilinear" or "nearest" (the voxel containing the point)
    torso_table_step: float = 0.002  # lift step (m) of the torso-carried spheres' cost tables; 0: off, else >= 1e-4
    body_clearance: float = 0.10  # real time: arm spheres nearer the person's body as last seen pay (m; 0: off)
    # (services.planner.body): the obstacle hinge, linear within its inner half; the default is the executor's
    # separation stop_m (0.05, where the guard holds the robot) plus the obstacle margin `clearance` (0.05)

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad value."""
        def finite(x: float) -> bool:  # an infinite weight or margin makes every cost inf * 0 or inf - inf: NaN
            return math.isfinite(x)

        lo, hi = SDF_RESOLUTION_M
        rules = {"sdf_resolution": f"{lo}-{hi} m", "torso_table_step": f"0 (off) or >= {MIN_TORSO_TABLE_STEP_M} m"}
        checks = [("w_smooth", finite(self.w_smooth) and self.w_smooth >= 0),
                  ("w_obstacle", finite(self.w_obstacle) and self.w_obstacle >= 0),
                  ("w_human", finite(self.w_human) and self.w_human >= 0),
                  ("clearance", finite(self.clearance) and self.clearance > 0),
                  ("self_clearance", finite(self.self_clearance)),
                  ("sdf_resolution", lo <= self.sdf_resolution <= hi),
                  ("human_points", self.human_points in (1, 7)),
                  ("human_point_radius", 0 <= self.human_point_radius <= 1),
                  ("human_interp", self.human_interp in ("trilinear", "nearest")),
                  ("torso_table_step", finite(self.torso_table_step)
                   and (self.torso_table_step == 0 or self.torso_table_step >= MIN_TORSO_TABLE_STEP_M)),
                  ("body_clearance", finite(self.body_clearance) and self.body_clearance >= 0)]
        for name, ok in checks:
            if not ok:
                rule = f" (must be {rules[name]})" if name in rules else ""
                raise ValueError(f"costs.{name}: bad value {getattr(self, name)!r}{rule}")


@dataclass
class PlannerConfig:
    """The planner's settings: device, goals, trajectory timing, and its components' configs.

    ``stomp`` configures the optimiser (its seed, device and dtype are this config's), ``cost`` the
    obstacle and human costs and the smoothness weight.
    """

    device: str = opt("cpu", help="torch device (cpu, cuda, cuda:1, ...)")
    dtype: str = opt("float32", help="torch float dtype", choices=("float32", "float64"))
    threads: int = opt(1, help="torch intra-op threads of the process (0: torch's default; at most 1024; >1 is slow "
                       "on shared cores, "
                       "and another count sums in another order: plans differ from the 7th digit)")
    fused_cost: bool = opt(True, help="evaluate the PR2 cost with the fused kernel (same numbers as the reference "
                           "StateCost path, fewer ops)")
    compile: bool = opt(True, help="torch.compile the fused cost and STOMP's rollout and update steps (once at "
                        "construction for the STOMP batch shape: ~10 s, ~1 s with inductor's disk cache; falls back "
                        "to eager if it fails)")
    cost_chunk_goals: int = opt(4, help="CPU, compiled cost: goals whose rollouts share one kernel call (a divisor "
                                "of K in [this / 2, this], else one call: the kernel's intermediates stay in "
                                "cache; 0: all in one call, as on CUDA)")
    seed: int = opt(0, help="base seed of STOMP's exploration noise (per step and goal)")
    goals: list[str] = opt(default_factory=list, help="cup names to plan for, in order (empty: every cup)")
    goal_choice: str = opt("total", help="the cost term that picks the goal each step: 'total' (the product), or "
                           "'human' (the least human-occupancy cost, the paper authors' choice)",
                           choices=("total", "human"))
    free_paths: bool = opt(True, help="a goal whose path passes into the scene or the robot is invalid for the step "
                           "while another goal's is free (services/planner/validity.py; the paper's protocol: off)")
    integrate_costs: bool = opt(True, help="weight obstacle/human costs by each waypoint's time at the velocity "
                                "limits (else sum them per waypoint)")
    goal_dwell_s: float = opt(1.0, help="with integrate_costs: seconds the robot is charged for the predicted "
                              "occupancy at its goal, where it stays to grasp (a held goal inside the human's "
                              "volume is not free; 0: off)")
    lookahead_s: float = opt(0.5, help="time the robot executes tau_best while a step is planned (s; the service "
                             "uses 0 in lock-step mode)")
    velocity_scale: float = opt(0.5, help="fraction of the joint velocity limits used to time trajectories")
    min_dt: float = opt(0.01, help="smallest time between waypoints (s)")
    goal_tol: float = opt(1e-3, help="a goal this close (joint-space norm) to q_t is reached: its trajectory holds it")
    anytime_min_iterations: int = opt(10, help="anytime: with a newer input waiting, stop STOMP after this many "
                                      "iterations (0: always run stomp.iterations; real time only, lock-step "
                                      "always runs them all)")
    off_path_tol: float = opt(0.05, help="joint-space distance beyond which the robot is taken as off tau_best")
    limit_tol: float = opt(JOINT_LIMIT_TOL, help="start configurations this far outside the limits are clamped, not "
                           "refused (default: the wire's JOINT_LIMIT_TOL, so a RobotState the planner accepts is one "
                           "it can plan from)")
    stomp: StompConfig = nested(
        StompConfig, help="STOMP, the optimiser of every goal's trajectory (its seed, device and dtype are the "
        "planner's)", hide=("seed", "device", "dtype", "compile"),
        field_help={"joint_noise_scale": "per-joint factors on noise_std (empty: velocity limits / their max)"})
    cost: CostConfig = nested(CostConfig, help="the costs STOMP minimises: smoothness weight, obstacle and human "
                              "occupancy terms")

    def validate(self) -> None:
        """Raise :class:`ConfigError` naming the first bad value (``planner.stomp.<name>``, ``planner.cost.<name>``)."""
        try:
            self.stomp_config().validate()
        except ValueError as exc:
            raise ConfigError(f"planner.{exc}") from None
        try:
            self.cost.validate()
        except ValueError as exc:
            raise ConfigError(f"planner.cost.{str(exc).removeprefix('costs.')}") from None
        if not 0 <= self.threads <= MAX_THREADS:
            raise ConfigError(f"planner.threads: bad value {self.threads!r} (must be 0-{MAX_THREADS}; 0: torch's "
                              "default)")
        checks = [("seed", self.seed >= 0),
                  ("lookahead_s", 0 <= self.lookahead_s < math.inf),
                  ("goal_dwell_s", math.isfinite(self.goal_dwell_s) and self.goal_dwell_s >= 0),
                  ("cost_chunk_goals", self.cost_chunk_goals >= 0),
                  ("anytime_min_iterations", self.anytime_min_iterations >= 0),
                  ("velocity_scale", 0 < self.velocity_scale <= 1), ("min_dt", MIN_DT_S <= self.min_dt <= MAX_DT_S),
                  ("off_path_tol", self.off_path_tol >= 0), ("limit_tol", self.limit_tol >= 0),
                  ("goal_tol", 0 <= self.goal_tol < math.inf), ("goal_choice", self.goal_choice in ("total", "human"))]
        for name, ok in checks:
            if not ok:
                raise ConfigError(f"planner.{name}: bad value {getattr(self, name)!r}")
        if self.stomp.waypoints > MAX_WAYPOINTS:  # a plan carries every waypoint of every goal
            raise ConfigError(f"planner.stomp.waypoints: at most {MAX_WAYPOINTS} (a plan's limit, docs/protocol.md), "
                              f"got {self.stomp.waypoints}")
        if len(set(self.goals)) != len(self.goals) or not all(self.goals):  # a plan names each goal once
            raise ConfigError(f"planner.goals: each cup once, got {','.join(self.goals)}")
        check_device(self.device, "planner.device")

    def stomp_config(self, joint_noise_scale: Sequence[float] | None = None) -> StompConfig:
        """``stomp`` with the planner's seed, device and dtype (``joint_noise_scale`` if not configured)."""
        scale = list(self.stomp.joint_noise_scale or joint_noise_scale or [])
        return dataclasses.replace(self.stomp, joint_noise_scale=scale, seed=self.seed, device=self.device,
                                   dtype=self.dtype, compile=self.compile)


@dataclass
class PlannerServiceConfig:
    """The ``[planner]`` section: how the service runs the planner, and the planner's config (same table)."""

    mode: str = opt("realtime", help="replan on a wall-clock period or on every ClockTick (lock-step: no lookahead)",
                    choices=("realtime", "lockstep"))
    period_s: float = opt(0.5, help="real-time: longest time between two published plans (s; trigger 'period': between "
                       "two step starts)")
    trigger: str = opt("event", help="real-time: 'event' starts a step as soon as a new prediction arrives or the "
                       "robot leaves its plan (period_s as the upper bound); 'period' replans on period_s only",
                       choices=TRIGGERS)
    input_timeout_s: float = opt(10.0, help="lock-step: longest wait for a tick's robot state / occupancy (s)")
    scene: str = opt("", help=SCENE_HELP + " (empty: pr2_two_cups)")
    stop_with: list[str] = opt(default_factory=list, help="end when one of these services (e.g. executor) "
                               "disappears after it was seen (comma-separated; how a compose run ends)")
    log_level: str = opt("INFO", help="log level", choices=LOG_LEVELS)
    planner: PlannerConfig = nested(PlannerConfig, inline=True, help="the planner's settings")

    def validate(self) -> None:
        """Check the planner's settings and the service's own."""
        self.planner.validate()
        if not (self.period_s > 0 and math.isfinite(self.period_s)):  # inf: the loop's wait overflowed and it died
            raise ConfigError(f"planner.period_s: must be a finite number > 0 (the executor holds the robot once its "
                              f"plan is older than its stale_limit_s), got {self.period_s}")
        if not self.input_timeout_s > 0:
            raise ConfigError(f"planner.input_timeout_s: must be > 0, got {self.input_timeout_s}")

    def planner_config(self) -> PlannerConfig:
        """The planner's config for this mode.

        In lock-step mode the executor's last RobotState of a tick already is the configuration the plan
        starts from, so there is no lookahead; in real time the plan starts ``lookahead_s`` ahead. The body term
        (``cost.body_clearance``, :mod:`services.planner.body`) is real time's: a lock-step run measures the paper's
        planners, and there is no separation guard to keep clear of.
        """
        if self.mode == "lockstep":
            return dataclasses.replace(self.planner, lookahead_s=0.0,
                                       cost=dataclasses.replace(self.planner.cost, body_clearance=0.0))
        return self.planner

