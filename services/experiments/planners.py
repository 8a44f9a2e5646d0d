"""The planners the experiments compare, and the settings every experiment shares.

* ``basic``: the paper's "basic STOMP": smoothness + obstacle cost, the human ignored (w_human = 0).
* ``least_penetration``: the paper's method: plus the penetration of the *predicted* occupancy.
* ``current``: plus the penetration of the human's *current* posture only (the predictor's ``current``
  method): the baseline of the paper's Fig. 8-9 top row.

``least_penetration`` and ``current`` run the same planner; they differ in the occupancy the predictor
publishes. Each planner is built once per experiment (goals by the scene, the cost compiled once) and
reset with the seed of each run.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from services.planner.config import CostConfig, PlannerConfig, StompConfig
from shared.scene import Scene

from .protocol import PRODUCT, Protocol

if TYPE_CHECKING:  # the planner (torch, its compiler) is imported to build one, not for foresight eval --help
    from services.planner.core import Planner

__all__ = ["Variant", "VARIANTS", "Timing", "build_planner"]


@dataclass(frozen=True)
class Variant:
    """One compared planner: the predictor's occupancy method and whether the human is costed."""

    name: str
    label: str
    method: str
    human_cost: bool


VARIANTS = {v.name: v for v in (Variant("basic", "basic STOMP", "prediction", False),
                                 Variant("least_penetration", "least penetration", "prediction", True),
                                 Variant("current", "current occupancy", "current", True))}
"""The compared planners by name."""


@dataclass(frozen=True)
class Timing:
    """How a run unfolds (the paper's section VI.B).

    Attributes:
        steps: Replanning steps per run (20).
        period_s: Simulated seconds per step: the robot executes this long while the next step is
            planned (the paper: 50 STOMP iterations take about 0.5 s).
        iterations: STOMP iterations per step (None: the protocol's, 50 in the product's, 51 in the paper's).
        robot_speed: Fraction of the PR2's joint velocity limits the planner times its trajectories with
            (the demo's collaborative speed).
        rollouts, reuse: STOMP's rollouts per iteration and how many of the previous iteration's best it reuses
            (None: the protocol's: 10 and 5 in both, the planner's defaults).
    """

    steps: int = 20
    period_s: float = 0.5
    iterations: int | None = None
    robot_speed: float = 0.25
    rollouts: int | None = None
    reuse: int | None = None


def build_planner(scene: Scene, goals: list[str], human_cost: bool, timing: Timing, compile: bool = True,
                  device: str = "cpu", w_human: float | None = None, protocol: Protocol = PRODUCT) -> Planner:
    """A lock-step planner for ``goals`` (cup names) of ``scene``.

    Args:
        scene: The scene.
        goals: Cup names, the robot's tasks.
        human_cost: False: basic STOMP (no human cost).
        timing: Iterations and robot speed.
        compile: torch.compile the fused cost and STOMP's steps.
        device: torch device.
        w_human: Weight of the human cost when ``human_cost`` (None: ``CostConfig``'s default).
        protocol: The experiment's protocol: its STOMP settings, cost composition and goal choice
            (:mod:`services.experiments.protocol`); ``timing.iterations`` overrides its iterations.
    """
    cost = CostConfig(body_clearance=0.0)  # lock-step: the paper's planners, no separation guard to keep clear of
    if not human_cost or w_human is not None:
        cost = dataclasses.replace(cost, w_human=w_human if human_cost else 0.0)
    p = protocol
    stomp = StompConfig(iterations=p.stomp_iterations(timing.iterations))
    reuse = timing.reuse if timing.reuse is not None else p.reuse
    if reuse is not None:
        stomp = dataclasses.replace(stomp, reuse=reuse)
    for name in ("rollouts", "waypoints", "noise_std"):
        if getattr(p, name) is not None:
            stomp = dataclasses.replace(stomp, **{name: getattr(p, name)})
    if timing.rollouts is not None:
        stomp = dataclasses.replace(stomp, rollouts=timing.rollouts)
    robot = None
    if p.uniform_noise:  # the authors' noise: the same for every arm joint; the torso keeps the product's scale
        from shared.robot import PR2

        robot = PR2.from_scene(scene, device=device)
        vel = robot.velocity_limits.double().cpu()
        torso = [n.endswith("torso_lift_joint") for n in robot.joint_names]
        scale = [float(v / vel.max()) if t else 1.0 for v, t in zip(vel, torso, strict=True)]
        stomp = dataclasses.replace(stomp, joint_noise_scale=scale)
    extra = {} if p.goal_dwell_s is None else {"goal_dwell_s": p.goal_dwell_s}
    cfg = PlannerConfig(goals=list(goals), stomp=stomp, velocity_scale=timing.robot_speed, lookahead_s=0.0, cost=cost,
                        compile=compile, device=device, integrate_costs=p.integrate_costs, goal_choice=p.goal_choice,
                        free_paths=p.free_paths, **extra)
    from services.planner.core import Planner

    return Planner(scene, cfg, robot=robot)
