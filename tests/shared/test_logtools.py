"""foresight log info / render on a small log written by the executor's MCAP writer."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from services.executor.foxglove import SceneBuilder
from services.executor.mcap_log import McapLog
from shared.logtools import format_info, main, read_log, step_title, step_views
from shared.protocol import ClockTick, HumanPose, Keys, OccupancyGrid, Plan, RobotState, encode
from shared.scene import load_scene

KEYS = Keys()


@pytest.fixture(scope="module")
def robot():
    import torch

    from shared.robot import PR2

    return PR2.from_scene(load_scene(None), device="cpu", dtype=torch.float32)


@pytest.fixture(scope="module")
def run_log(tmp_path_factory, robot) -> Path:
    """Two lock-step replanning steps with every message type, one malformed payload."""
    scene = load_scene(None)
    path = tmp_path_factory.mktemp("log") / "run.mcap"
    q0 = robot.q_start.numpy().astype(np.float64)
    goals = [q0 + np.r_[0, 0.4, 0.2, 0.1, 0.5, 0, 0, 0], q0 + np.r_[0, -0.4, 0.1, 0.2, 0.4, 0, 0, 0]]
    text = (Path(__file__).resolve().parents[2] / "shared/data/scenes/pr2_two_cups.toml").read_text()
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


def test_info_lists_channels_schemas_and_counts(run_log, capsys) -> None:
    assert main(["info", str(run_log)]) == 0
    out = capsys.readouterr().out
    assert "complete" in out and "TRUNCATED" not in out
    lines = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.startswith("  ") and "/" in ln}
    assert lines[KEYS.plan][1:] == ["foresight.Plan", "jsonschema", "msgpack", "2"]
    assert lines[KEYS.robot_state][-1] == "2" and lines[KEYS.occupancy][-1] == "2"
    assert lines["/viz/plan"][1:] == ["foxglove.SceneUpdate", "jsonschema", "json", "2"]
    assert lines["/foresight/rejected"][-1] == "1"
    assert "scene.toml" in out and f"rejected:  {KEYS.plan}: 1" in out and "mode=lockstep" in out
    assert main(["info", str(run_log), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["complete"] and d["rejected"] == {KEYS.plan: 1}
    assert {c["topic"]: c["messages"] for c in d["channels"]}[KEYS.clock] == 2


def test_info_on_a_truncated_file(run_log, tmp_path) -> None:
    data = run_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) - 300])  # footer and part of the summary gone
    lf = read_log(cut)
    assert not lf.complete
    assert "TRUNCATED" in format_info(lf)
    assert lf.channels  # what was written before is still listed


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
    log = McapLog(path, KEYS, None)
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
    log.close()
    title = step_title(step_views(read_log(path, keep=lambda ch: ch.message_encoding == "msgpack"))[6])
    assert "Replanning step 6 (t = 1.25 s into the run)" in title
    assert "occupancy of pose 30 at t = 1.00 s (prediction)" in title
    assert "tick -1" not in title and "1700000000" not in title


def test_render_writes_pngs(run_log, tmp_path, capsys) -> None:
    out = tmp_path / "step1.png"
    assert main(["render", str(run_log), "--step", "1", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    import matplotlib.image as mpimg

    img = mpimg.imread(out)
    assert img.shape[0] > 500 and img.shape[1] > 1000
    assert main(["render", str(run_log), "--all", "--out", str(tmp_path / "all")]) == 0
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == ["step_000.png", "step_001.png"]


@pytest.mark.parametrize("argv, message", [
    (["info", "/nonexistent.mcap"], "not found"),
    (["render", "{log}", "--step", "7", "--out", "x.png"], "no plan for step 7"),
    (["render", "{log}", "--out", "x.png"], "--step N or --all"),
    (["info", "{bad}"], "not an MCAP file"),
])
def test_errors_are_one_line(run_log, tmp_path, capsys, argv, message) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"hello, this is not mcap at all")
    argv = [a.format(log=run_log, bad=bad) for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
