"""A known state of a run (robot, plan, occupancy, human, posterior) for the scene tests."""

from __future__ import annotations

import numpy as np
import pytest

from shared.protocol import ClassPosterior, HumanPose, OccupancyGrid, Plan, RobotState
from shared.scene import load_scene

SCENE = load_scene(None)


@pytest.fixture(scope="session")
def builder():
    from shared.foxglove.scene import default_builder

    return default_builder(SCENE)


def state(pr2, holding: bool = False) -> RobotState:
    """The robot at its start configuration."""
    return RobotState(stamp=1.0, tick=5, joint_names=list(pr2.joint_names), goal=1, reached=False, holding=holding,
                      reason="", q=pr2.q_start.numpy().astype(np.float64), qd=np.zeros(len(pr2.joint_names)))


def plan(pr2, chosen: int = 1) -> Plan:
    """Two straight joint-space paths from the start, goal ``chosen`` chosen; the other goal's cost infinite."""
    q0 = pr2.q_start.numpy().astype(np.float64)
    goals = [q0 + np.r_[0, 0.4, 0.2, 0.1, 0.5, 0, 0, 0], q0 + np.r_[0, -0.4, 0.1, 0.2, 0.4, 0, 0, 0]]
    traj = np.stack([np.linspace(q0, g, 12) for g in goals]).astype(np.float32)
    cost = np.array([np.inf, 2.0])
    return Plan(stamp=1.0, tick=5, step=3, goal_names=["blue_cup", "red_cup"], joint_names=list(pr2.joint_names),
                dt=0.1, chosen=chosen, planning_ms=12.5, occupancy_tick=5, occupancy_index=40, trajectories=traj,
                cost_smoothness=cost, cost_obstacle=np.where(np.isinf(cost), np.inf, 0.0), cost_human=cost,
                cost_total=2 * cost,
                valid=np.array([False, True]))


def occupancy() -> OccupancyGrid:
    """Two blocks of voxels, p = 0.8 and p = 0.03 (the second below the drawing threshold)."""
    grid = np.zeros(SCENE.grid.dims, np.float32)
    grid[18:24, 12:20, 15:22] = 0.8
    grid[2:4, 2:4, 2:4] = 0.03
    return OccupancyGrid.from_dense(grid, SCENE.grid.origin, SCENE.grid.resolution, stamp=1.0, tick=5,
                                    tick_last=True, demo_id=0, index=40, method="prediction")


def pose() -> HumanPose:
    return HumanPose(stamp=1.0, tick=5, tick_last=True, demo_id=1, index=0,
                     features=np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5]))


def posterior() -> ClassPosterior:
    return ClassPosterior(stamp=1.0, tick=5, demo_id=1, index=40, class_names=["blue_cup", "red_cup"],
                          posterior=np.array([0.25, 0.75]), log_likelihood=np.array([-3.0, -2.0]))
