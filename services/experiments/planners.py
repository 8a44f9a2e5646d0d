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

from services.planner.core import Planner, PlannerConfig
from services.planner.costs import CostConfig
from services.planner.stomp import StompConfig
from shared.scene import Scene

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
        iterations: STOMP iterations per step (50).
        robot_speed: Fraction of the PR2's joint velocity limits the planner times its trajectories with
            (the demo's collaborative speed).
    """

    steps: int = 20
    period_s: float = 0.5
    iterations: int = 50
    robot_speed: float = 0.25


def build_planner(scene: Scene, goals: list[str], human_cost: bool, timing: Timing, compile: bool = True,
                  device: str = "cpu", w_human: float | None = None) -> Planner:
    """A lock-step planner for ``goals`` (cup names) of ``scene``.

    Args:
        scene: The scene.
        goals: Cup names, the robot's tasks.
        human_cost: False: basic STOMP (no human cost).
        timing: Iterations and robot speed.
        compile: torch.compile the fused cost and STOMP's steps.
        device: torch device.
        w_human: Weight of the human cost when ``human_cost`` (None: ``CostConfig``'s default).
    """
    cost = CostConfig()
    if not human_cost or w_human is not None:
        cost = dataclasses.replace(cost, w_human=w_human if human_cost else 0.0)
    cfg = PlannerConfig(goals=list(goals), stomp=StompConfig(iterations=timing.iterations),
                        velocity_scale=timing.robot_speed, lookahead_s=0.0, cost=cost, compile=compile, device=device)
    return Planner(scene, cfg)
