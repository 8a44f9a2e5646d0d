"""Messages of every type for the recording tests, and the robot model."""

from __future__ import annotations

import numpy as np
import pytest

from shared.protocol import ClockTick, HumanPose, Keys, OccupancyGrid, Plan, RobotState, encode
from shared.scene import load_scene

SCENE = load_scene(None)
KEYS = Keys()


@pytest.fixture(scope="session")
def pr2():
    import torch

    from shared.robot import PR2

    return PR2.from_scene(SCENE, device="cpu", dtype=torch.float32)


def blob(tick: int, index: int, stamp: float) -> OccupancyGrid:
    """A block of occupied voxels (p = 0.8) in front of the robot."""
    grid = np.zeros(SCENE.grid.dims, np.float32)
    grid[18 + tick % 3: 24 + tick % 3, 12:20, 15:22] = 0.8
    return OccupancyGrid.from_dense(grid, SCENE.grid.origin, SCENE.grid.resolution, stamp=stamp, tick=tick,
                                    tick_last=True, demo_id=0, index=index, method="prediction")


def two_goal_plan(q0: np.ndarray, names: list[str], chosen: int) -> Plan:
    """Straight lines from ``q0`` to two goals, goal ``chosen`` chosen."""
    goals = [q0 + np.r_[0, 0.4, 0.2, 0.1, 0.5, 0, 0, 0], q0 + np.r_[0, -0.4, 0.1, 0.2, 0.4, 0, 0, 0]]
    traj = np.stack([np.linspace(q0, g, 15) for g in goals]).astype(np.float32)
    cost = np.array([1.0, 2.0])
    return Plan(stamp=0.0, tick=0, step=0, goal_names=["blue_cup", "red_cup"], joint_names=list(names), dt=0.1,
                chosen=chosen, planning_ms=1.0, occupancy_tick=0, occupancy_index=0, trajectories=traj,
                cost_smoothness=cost, cost_obstacle=cost * 0, cost_human=cost, cost_total=2 * cost,
                valid=np.ones(2, bool))


def sample_messages(pr2) -> list[tuple[str, bytes]]:
    q0 = pr2.q_start.numpy().astype(np.float64)
    feats = np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])
    return [
        (KEYS.pose, encode(HumanPose(stamp=0.0, tick=0, tick_last=True, demo_id=1, index=0, features=feats))),
        (KEYS.occupancy, encode(blob(0, 0, 0.0))),
        (KEYS.robot_state, encode(RobotState(stamp=0.0, tick=0, joint_names=pr2.joint_names, goal=-1, reached=False,
                                             holding=True, reason="waiting", q=q0, qd=np.zeros(8)))),
        (KEYS.plan, encode(two_goal_plan(q0, pr2.joint_names, chosen=1))),
        (KEYS.clock, encode(ClockTick(stamp=0.0, tick=0, period=0.2))),
    ]

