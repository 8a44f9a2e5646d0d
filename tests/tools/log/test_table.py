"""``foresight log table``: the step table of a logged run, as the demo prints it (two lock-step steps here)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tools.log.cli import main


def test_the_table_has_a_row_per_step_and_the_outcome(run_log, capsys) -> None:
    assert main(["table", str(run_log)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[:4] == ["step", "t", "(s)", "chosen"]
    assert lines[1].split()[:5] == ["0", "0.00", "blue_cup", "1.500", "4.000"]
    assert lines[2].split()[:5] == ["1", "0.20", "red_cup", "5.000", "1.200"]
    assert lines[3] == "switch step: 1 (t = 0.20 s)"
    assert lines[4] == "goal reached: no" and lines[5].startswith("interference cost")
    assert main(["table", str(run_log), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["chosen_goal_per_step"] == ["blue_cup", "red_cup"] and summary["switch_step"] == 1


def test_a_log_without_plans_is_one_clear_error(tmp_path, capsys) -> None:
    from shared.protocol import Keys
    from shared.recording.writer import McapLog

    path = tmp_path / "empty.mcap"
    McapLog(path, Keys()).close()
    with pytest.raises(SystemExit) as exc:
        main(["table", str(path)])
    assert exc.value.code == 2
    assert "no plans logged" in capsys.readouterr().err


def test_the_final_grid_is_chosen_as_the_demo_chooses_it(tmp_path, robot) -> None:
    """The newest grid by (tick, stamp, ...), not the last in the file: ``log table`` and the demo score one grid."""
    from services.run_log import recorder_from_log
    from shared.protocol import Keys, OccupancyGrid, Plan, encode
    from shared.recording.reader import read_log
    from shared.recording.writer import McapLog
    from shared.scene import load_scene
    from tools.log.table import run_summary

    keys, scene = Keys(), load_scene(None)
    path = tmp_path / "late.mcap"
    log = McapLog(path, keys)
    q0 = robot.q_start.numpy().astype(np.float32)
    log.on_sample(keys.plan, encode(Plan(
        stamp=0.0, tick=0, step=0, goal_names=["blue_cup"], joint_names=robot.joint_names, dt=0.1, chosen=0,
        planning_ms=1.0, occupancy_tick=-1, occupancy_index=-1, trajectories=np.stack([np.stack([q0] * 4)]),
        cost_smoothness=np.ones(1), cost_obstacle=np.zeros(1), cost_human=np.zeros(1), cost_total=np.ones(1),
        valid=np.ones(1, bool))))
    dims = scene.grid.dims
    for tick, method in ((1, "prediction"), (0, "current")):  # the tick-0 grid is logged late
        grid = OccupancyGrid.from_dense(np.zeros(dims, np.float32), scene.grid.origin, scene.grid.resolution,
                                        stamp=0.2 * tick, tick=tick, tick_last=True, demo_id=3, index=tick,
                                        method=method)
        log.on_sample(keys.occupancy, encode(grid))
    log.close()
    summary = run_summary(read_log(path, keep=lambda ch: True))
    assert summary.scored_against == "final prediction"
    recorder = recorder_from_log(path, keys)
    assert recorder is not None and recorder.snapshot()[2].tick == 1


def test_a_log_without_occupancy_grids_says_its_interference_is_not_scored(run_log, tmp_path, capsys) -> None:
    """It printed "interference cost ... (final prediction): 0.0000" with no prediction in the log (a review)."""
    from shared.protocol import Keys
    from shared.recording.reader import read_log
    from shared.recording.writer import McapLog

    keys = Keys()
    path = tmp_path / "no_occupancy.mcap"
    log = McapLog(path, keys)
    for m in read_log(run_log, keep=lambda ch: ch.message_encoding == "msgpack").messages:
        if m.topic != keys.occupancy:
            log.on_sample(m.topic, m.data)
    log.close()
    assert main(["table", str(path)]) == 0
    out = capsys.readouterr().out
    assert "interference cost of the executed trajectory: not scored (no occupancy prediction was logged)" in out
    assert "0.0000" not in out
    assert main(["table", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["interference_scored"] is False
    assert main(["table", str(run_log), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["interference_scored"] is True


def test_a_realtime_log_counts_the_plans_the_executor_adopted_in_table_and_render(tmp_path, robot) -> None:
    """Table, render and the demo's summary (from the log) count the plans the executor took, with the same numbers.

    An interrupted run said "interrupted after 11 plans" and `log render` "steps 0..15" where the executor adopted 9:
    they kept every plan stamped before the robot's last state (a review). Here plan 1 is overtaken by plan 2 before
    the next state, and plan 3 comes after the last state: the executor adopts plans 0 and 2.
    """
    from services.run_log import recorder_from_log
    from services.scenario import summarise
    from shared.protocol import Keys, Plan, RobotState, encode
    from shared.recording.reader import read_log
    from shared.recording.writer import McapLog
    from tools.log.steps import step_views
    from tools.log.table import WANTED, run_summary

    keys, t0 = Keys(), 1_700_000_000.0
    q0 = robot.q_start.numpy().astype(np.float64)
    now = [t0]
    path = tmp_path / "rt.mcap"
    log = McapLog(path, keys, None, clock=lambda: int(now[0] * 1e9))

    def state(t: float) -> None:
        now[0] = t0 + t
        log.on_sample(keys.robot_state, encode(RobotState(stamp=t0 + t, tick=-1, joint_names=robot.joint_names,
                                                          goal=0, reached=False, holding=False, reason="", q=q0,
                                                          qd=np.zeros(8))))

    def plan(step: int, made: float, arrives: float) -> None:
        now[0] = t0 + arrives
        traj = np.stack([np.linspace(q0, q0 + 0.1, 5)] * 2).astype(np.float32)
        log.on_sample(keys.plan, encode(Plan(stamp=t0 + made, tick=-1, step=step, goal_names=["blue_cup", "red_cup"],
                                             joint_names=robot.joint_names, dt=0.1, chosen=0, planning_ms=10.0,
                                             occupancy_tick=-1, occupancy_index=0, trajectories=traj,
                                             cost_smoothness=np.ones(2), cost_obstacle=np.zeros(2),
                                             cost_human=np.zeros(2), cost_total=np.ones(2), valid=np.ones(2, bool))))

    state(0.0)
    plan(0, 0.0, 0.01)
    state(0.02)  # adopts plan 0
    plan(1, 0.02, 0.03)
    plan(2, 0.02, 0.035)  # before the next state: plan 1 is never taken
    state(0.04)  # adopts plan 2
    plan(3, 0.03, 0.05)  # stamped before the last state, but it came after it
    log.close()
    lf = read_log(path, keep=lambda ch: ch.schema_name in WANTED | {"foresight.HumanPose"}
                  and ch.message_encoding == "msgpack")
    assert [s["step"] for s in run_summary(lf).steps] == [0, 2]
    assert sorted(step_views(lf)) == [0, 2]
    plans, states, final, posteriors = (recorder := recorder_from_log(path, keys)).snapshot()
    demo = summarise(plans, states, final, posteriors, robot, "", str(path), received=recorder.plan_arrivals())
    assert [s["step"] for s in demo.steps] == [0, 2]
