"""Replanning steps of a log: plans paired with the messages they were made from, and their titles."""

from __future__ import annotations

import numpy as np

from shared.protocol import Keys, OccupancyGrid, Plan, RobotState, encode
from shared.recording.reader import read_log
from shared.recording.writer import McapLog
from shared.scene import load_scene
from tools.log.steps import step_title, step_views

KEYS = Keys()


def test_step_views_pair_plans_with_their_occupancy(run_log) -> None:
    lf = read_log(run_log, keep=lambda ch: ch.message_encoding == "msgpack")
    views = step_views(lf)
    assert sorted(views) == [0, 1]
    assert views[1].plan.chosen == 1
    assert views[1].occupancy is not None and views[1].occupancy.tick == 0  # the prediction plan 1 used
    assert views[1].pose is not None and views[1].pose.index == 0 and views[1].first_pose.index == 0
    assert views[1].state is not None and views[1].state.tick == 1


def test_step_titles_lockstep_and_realtime(run_log, tmp_path, robot) -> None:
    lf = read_log(run_log, keep=lambda ch: ch.message_encoding == "msgpack")
    title = step_title(step_views(lf)[1])
    assert "Replanning step 1 (tick 1, t = 0.20 s simulated)" in title
    assert "occupancy of tick 0 / pose 0 (prediction)" in title
    # real time: wall-clock stamps, tick -1; the title counts seconds from the first robot state
    t0 = 1_700_000_000.0
    scene = load_scene(None)
    q0 = robot.q_start.numpy().astype(np.float64)
    path = tmp_path / "rt.mcap"
    now = [t0]  # the log's clock: the wall clock the states are stamped on (the executor's)
    log = McapLog(path, KEYS, None, clock=lambda: int(now[0] * 1e9))
    grid = np.zeros(scene.grid.dims, np.float32)
    grid[18:24, 10:18, 14:20] = 0.5
    log.on_sample(KEYS.robot_state, encode(RobotState(stamp=t0, tick=-1, joint_names=robot.joint_names, goal=-1,
                                                      reached=False, holding=False, reason="", q=q0, qd=np.zeros(8))))
    log.on_sample(KEYS.occupancy, encode(OccupancyGrid.from_dense(grid, scene.grid.origin, scene.grid.resolution,
                                                                  stamp=t0 + 1.0, tick=-1, tick_last=True, demo_id=0,
                                                                  index=30, method="prediction")))
    traj = np.stack([np.linspace(q0, q0 + 0.1, 5)] * 2).astype(np.float32)
    log.on_sample(KEYS.plan, encode(Plan(stamp=t0 + 1.25, tick=-1, step=6, goal_names=["blue_cup", "red_cup"],
                                         joint_names=robot.joint_names, dt=0.1, chosen=0, planning_ms=12.0,
                                         occupancy_tick=-1, occupancy_index=30, trajectories=traj,
                                         cost_smoothness=np.ones(2), cost_obstacle=np.zeros(2), cost_human=np.zeros(2),
                                         cost_total=np.ones(2), valid=np.ones(2, bool))))
    now[0] = t0 + 1.3
    log.on_sample(KEYS.robot_state, encode(RobotState(stamp=t0 + 1.3, tick=-1, joint_names=robot.joint_names, goal=0,
                                                      reached=False, holding=False, reason="", q=q0, qd=np.zeros(8))))
    log.close()
    title = step_title(step_views(read_log(path, keep=lambda ch: ch.message_encoding == "msgpack"))[0])
    assert "Plan 0 (t = 1.25 s into the run)" in title  # its row in `foresight log table`, not the planner's count
    assert "occupancy of pose 30 at t = 1.00 s (prediction)" in title
    assert "tick -1" not in title and "1700000000" not in title


def test_a_plan_put_on_another_key_under_the_prefix_is_logged_but_is_not_the_runs(tmp_path, robot) -> None:
    """The log keeps every message under the prefix; the scene drew, and the tools read, any Plan as the robot's."""
    from shared.foxglove.scene import SceneBuilder

    keys = Keys("lab")
    q0 = robot.q_start.numpy().astype(np.float64)
    path = tmp_path / "run.mcap"
    log = McapLog(path, keys, SceneBuilder(load_scene(None), robot), run_metadata={"prefix": "lab"})

    def plan(step: int) -> bytes:
        traj = np.stack([np.linspace(q0, q0 + 0.1 * (step + 1), 5)] * 2).astype(np.float32)
        return encode(Plan(stamp=0.5 * step, tick=step, step=step, goal_names=["blue_cup", "red_cup"],
                           joint_names=robot.joint_names, dt=0.1, chosen=0, planning_ms=1.0, occupancy_tick=-1,
                           occupancy_index=-1, trajectories=traj, cost_smoothness=np.ones(2),
                           cost_obstacle=np.zeros(2), cost_human=np.zeros(2), cost_total=np.ones(2),
                           valid=np.ones(2, bool)))

    log.on_sample(keys.plan, plan(0))
    log.on_sample("lab/other/thing", plan(1))  # a valid plan, on a key the planner does not own
    log.close()
    lf = read_log(path, keep=lambda ch: True)
    assert len(lf.topic_messages("lab/other/thing")) == 1  # nothing logged is lost
    assert len(lf.topic_messages("/viz/plan")) == 1 and sorted(step_views(lf)) == [0]


def test_a_log_of_a_schema_version_this_build_does_not_read_is_said_so_not_empty(run_log, tmp_path) -> None:
    """A review rewrote a demo's MCAP with `_v` 3: `log table` said 'no plans logged', `log render` 'no Plan
    messages': a newer build's log read as an empty run, nothing naming the version."""
    import dataclasses

    import msgpack
    import pytest

    from shared.runtime import UserError
    from tools.log.steps import decode_all

    lf = read_log(run_log, keep=lambda ch: ch.message_encoding == "msgpack")
    assert decode_all(lf, "foresight.Plan", Plan)  # as written

    def bump(data: bytes) -> bytes:
        raw = msgpack.unpackb(data, raw=False)
        return msgpack.packb({**raw, "_v": 3}, use_bin_type=True)

    newer = dataclasses.replace(lf, messages=[dataclasses.replace(m, data=bump(m.data)) for m in lf.messages])
    with pytest.raises(UserError, match=r"its 2 Plan message\(s\) are of a schema version this build does not read "
                       r"\(Plan\._v: schema version '3', this build speaks 2 and reads 1, 2\)"):
        decode_all(newer, "foresight.Plan", Plan)
