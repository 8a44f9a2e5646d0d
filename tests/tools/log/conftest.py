"""A small log written by the recording writer: two lock-step replanning steps with every message type."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shared.foxglove.scene import SceneBuilder
from shared.protocol import ClockTick, HumanPose, Keys, OccupancyGrid, Plan, RobotState, encode
from shared.recording.writer import McapLog
from shared.scene import load_scene

KEYS = Keys()
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def robot():
    import torch

    from shared.robot import PR2

    return PR2.from_scene(load_scene(None), device="cpu", dtype=torch.float32)


@pytest.fixture(scope="session")
def run_log(tmp_path_factory, robot) -> Path:
    """Two lock-step replanning steps with every message type, one malformed payload."""
    scene = load_scene(None)
    path = tmp_path_factory.mktemp("log") / "run.mcap"
    q0 = robot.q_start.numpy().astype(np.float64)
    goals = [q0 + np.r_[0, 0.4, 0.2, 0.1, 0.5, 0, 0, 0], q0 + np.r_[0, -0.4, 0.1, 0.2, 0.4, 0, 0, 0]]
    text = (REPO / "shared/data/scenes/pr2_two_cups.toml").read_text()
    log = McapLog(path, KEYS, SceneBuilder(scene, robot), scene_text=text, run_metadata={"mode": "lockstep",
                                                                                         "steps": "2"})
    feats = np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])
    for n in range(2):
        grid = np.zeros(scene.grid.dims, np.float32)
        grid[18:24, 10:18, 14:20] = np.linspace(0.2, 1.0, 6)[None, None, :]
        traj = np.stack([np.linspace(q0, g, 12) for g in goals]).astype(np.float32)
        msgs = [
            (KEYS.robot_state, RobotState(stamp=0.2 * n, tick=n, joint_names=robot.joint_names, goal=n - 1,
                                          reached=False, holding=n == 0, reason="waiting for the first plan" if n == 0
                                          else "", q=q0, qd=np.zeros(8))),
            (KEYS.clock, ClockTick(stamp=0.2 * n, tick=n, period=0.2)),
            (KEYS.pose, HumanPose(stamp=0.2 * n, tick=n, tick_last=True, demo_id=3, index=n,
                                  features=feats + 0.2 * n)),
            (KEYS.occupancy, OccupancyGrid.from_dense(grid, scene.grid.origin, scene.grid.resolution,
                                                      stamp=0.2 * n, tick=n, tick_last=True, demo_id=3, index=n,
                                                      method="prediction")),
            (KEYS.plan, Plan(stamp=0.2 * n, tick=n, step=n, goal_names=["blue_cup", "red_cup"],
                             joint_names=robot.joint_names, dt=0.1, chosen=n, planning_ms=12.0, occupancy_tick=n - 1,
                             occupancy_index=n - 1, trajectories=traj, cost_smoothness=np.ones(2),
                             cost_obstacle=np.zeros(2), cost_human=np.array([0.5, 3.0]) if n == 0 else
                             np.array([4.0, 0.2]), cost_total=np.array([1.5, 4.0]) if n == 0 else np.array([5.0, 1.2]),
                             valid=np.ones(2, bool))),
        ]
        for key, msg in msgs:
            log.on_sample(key, encode(msg))
    log.on_sample(KEYS.plan, b"not msgpack \xc1")
    log.close()
    return path
