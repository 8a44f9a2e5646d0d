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
from dataclasses import dataclass

from shared.config import LOG_LEVELS, ConfigError, nested, opt
from shared.devices import check_device
from shared.protocol.limits import JOINT_LIMIT_TOL, MAX_DT_S, MAX_WAYPOINTS, MIN_DT_S
from shared.scene import SCENE_HELP

from .costs import CostConfig
from .replan import TRIGGERS
from .stomp import StompConfig

__all__ = ["PlannerConfig", "PlannerServiceConfig"]


@dataclass
class PlannerConfig:
    """The planner's settings: device, goals, trajectory timing, and its components' configs.

    ``stomp`` configures the optimiser (its seed, device and dtype are this config's), ``cost`` the
    obstacle and human costs and the smoothness weight.
    """

    device: str = opt("cpu", help="torch device (cpu, cuda, cuda:1, ...)")
    dtype: str = opt("float32", help="torch float dtype", choices=("float32", "float64"))
    threads: int = opt(1, help="torch intra-op threads of the process (0: torch's default; >1 is slow on shared cores)")
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
        checks = [("seed", self.seed >= 0), ("threads", self.threads >= 0), ("lookahead_s", self.lookahead_s >= 0),
                  ("goal_dwell_s", math.isfinite(self.goal_dwell_s) and self.goal_dwell_s >= 0),
                  ("cost_chunk_goals", self.cost_chunk_goals >= 0),
                  ("anytime_min_iterations", self.anytime_min_iterations >= 0),
                  ("velocity_scale", 0 < self.velocity_scale <= 1), ("min_dt", MIN_DT_S <= self.min_dt <= MAX_DT_S),
                  ("off_path_tol", self.off_path_tol >= 0), ("limit_tol", self.limit_tol >= 0),
                  ("goal_tol", self.goal_tol >= 0), ("goal_choice", self.goal_choice in ("total", "human"))]
        for name, ok in checks:
            if not ok:
                raise ConfigError(f"planner.{name}: bad value {getattr(self, name)!r}")
        if self.stomp.waypoints > MAX_WAYPOINTS:  # a plan carries every waypoint of every goal
            raise ConfigError(f"planner.stomp.waypoints: at most {MAX_WAYPOINTS} (a plan's limit, docs/protocol.md), "
                              f"got {self.stomp.waypoints}")
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
    period_s: float = opt(0.5, help="real-time: longest time between two replanning steps (s)")
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
        if not self.period_s > 0:
            raise ConfigError(f"planner.period_s: must be > 0, got {self.period_s}")
        if not self.input_timeout_s > 0:
            raise ConfigError(f"planner.input_timeout_s: must be > 0, got {self.input_timeout_s}")

    def planner_config(self) -> PlannerConfig:
        """The planner's config for this mode.

        In lock-step mode the executor's last RobotState of a tick already is the configuration the plan
        starts from, so there is no lookahead; in real time the plan starts ``lookahead_s`` ahead.
        """
        if self.mode == "lockstep":
            return dataclasses.replace(self.planner, lookahead_s=0.0)
        return self.planner

