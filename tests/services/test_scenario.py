"""The scenario's pure pieces: choosing the human's demonstration and the summary (its interference measure is
tested in tests/services/experiments/test_measures.py)."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest
import torch

from services.run_log import RunRecorder
from services.run_table import table_header
from services.scenario import Summary, choose_demonstration, summarise
from shared.atomic_file import atomic_write
from shared.protocol import ClassPosterior, OccupancyGrid, Plan, RobotState
from shared.runtime import UserError
from shared.synthetic import generate_library


class PointRobot:
    """One sphere of radius 0 at the first three joint values."""

    lower = torch.zeros(3)
    sphere_radii = torch.zeros(1)

    def sphere_centers(self, q: torch.Tensor) -> torch.Tensor:
        return q[..., None, :3]


def _grid(p: float) -> OccupancyGrid:
    dense = np.zeros((4, 4, 4))
    dense[1, 1, 1] = p
    return OccupancyGrid.from_dense(dense, np.zeros(3), 0.1, stamp=0.0, tick=0, tick_last=True, demo_id=0, index=0,
                                    method="prediction")


def _plan(tick: int, chosen: int, costs: list[float], stamp: float | None = None, step: int | None = None) -> Plan:
    return Plan(stamp=0.2 * tick if stamp is None else stamp, tick=tick, step=tick if step is None else step,
                goal_names=["blue_cup", "red_cup"], joint_names=["a", "b", "c"],
                dt=0.1, chosen=chosen, planning_ms=10.0, occupancy_tick=tick - 1, occupancy_index=0,
                trajectories=np.zeros((2, 3, 3), np.float32), cost_smoothness=np.zeros(2), cost_obstacle=np.zeros(2),
                cost_human=np.zeros(2), cost_total=np.array(costs), valid=np.ones(2, bool))


def test_choose_demonstration_is_seeded_and_spreads_the_motion():
    lib = generate_library(8, 4, seed=1)
    a = choose_demonstration(lib, steps=20, seed=3)
    assert a == choose_demonstration(lib, steps=20, seed=3)
    assert a.demo.class_name == "red_cup" and a.samples_per_tick == 5
    assert choose_demonstration(lib, steps=20, seed=3, human_class="0").demo.label == 0
    with pytest.raises(UserError, match="nope"):
        choose_demonstration(lib, steps=20, seed=0, human_class="nope")
    with pytest.raises(UserError, match=r"'blue_cupp': not a class .*; did you mean blue_cup\?$"):  # as options do
        choose_demonstration(lib, steps=20, seed=0, human_class="blue_cupp")
    paper_like = dataclasses.replace(lib, class_names=[f"compound_{i}" for i in range(8)])
    with pytest.raises(UserError, match=r"'blue_cup': not a class .*; the paper's library: --human-class compound_1"):
        choose_demonstration(paper_like, steps=20, seed=0, human_class="blue_cup")  # the demo's default


def test_summary_switch_step_and_goal_reached():
    plans = [_plan(0, 1, [2.0, 1.0]), _plan(1, 1, [2.0, 1.5]), _plan(2, 0, [1.0, 3.0]), _plan(3, 0, [1.0, 3.0])]
    states = [RobotState(stamp=0.1 * i, tick=i, joint_names=["a", "b", "c"], goal=0, reached=i == 3, holding=False,
                         reason="", q=np.full(3, 0.15), qd=np.zeros(3)) for i in range(4)]
    s = summarise(plans, states, _grid(0.5), {}, PointRobot(), "red_cup", None)
    assert s.chosen_goal_per_step == ["red_cup", "red_cup", "blue_cup", "blue_cup"]
    assert s.switch_step == 2 and s.reached and s.reached_step == 3
    assert s.interference_cost == pytest.approx(128 / 255 * 0.3)  # 0.5 quantised to 8 bits, 3 intervals of 0.1 s
    assert s.to_json()["switch_step"] == 2
    text = "\n".join(s.lines())
    assert "switch step: 2 (t = 0.40 s)" in text
    assert "goal reached: yes, during step 3 (t = 0.30 s)" in text
    assert isinstance(s, Summary)


def test_a_goal_reached_before_the_robot_turned_to_another_is_not_the_runs():
    """The robot at goal 1 at step 1, then going for goal 0 to the end: it did not reach its goal (it said step 1)."""
    plans = [_plan(0, 1, [2.0, 1.0]), _plan(1, 1, [2.0, 1.5]), _plan(2, 0, [1.0, 3.0]), _plan(3, 0, [1.0, 3.0])]
    states = [RobotState(stamp=0.1 * i, tick=i, joint_names=["a", "b", "c"], goal=1 if i < 2 else 0, reached=i == 1,
                         holding=False, reason="", q=np.full(3, 0.15), qd=np.zeros(3)) for i in range(4)]
    s = summarise(plans, states, _grid(0.5), {}, PointRobot(), "red_cup", None)
    assert not s.reached and s.reached_step is None
    assert s.left_goal == {"goal": "red_cup", "reached_t_s": pytest.approx(0.1), "left_t_s": pytest.approx(0.2)}
    assert "goal reached: no (it reached red_cup at t = 0.10 s and left it at 0.20 s, turned to another goal)" in (
        s.lines())


def test_a_goal_reached_left_and_gone_back_to_is_not_reached_until_it_is_there_again():
    """A review (the README's real-time run): goal 1 reached at 2.88 s, then goal 0, then goal 1 again to the end,
    never there: the summary said 'goal reached: yes, during step 85 (t = 2.88 s)'."""
    plans = [_plan(k, 1 if k < 2 or k > 3 else 0, [2.0, 1.0]) for k in range(6)]
    goals, reached = [1, 1, 0, 0, 1, 1], [False, True, False, False, False, False]
    states = [RobotState(stamp=0.1 * i, tick=i, joint_names=["a", "b", "c"], goal=goals[i], reached=reached[i],
                         holding=False, reason="", q=np.full(3, 0.15), qd=np.zeros(3)) for i in range(6)]
    s = summarise(plans, states, _grid(0.5), {}, PointRobot(), "red_cup", None)
    assert not s.reached and s.left_goal is not None and s.left_goal["left_t_s"] == pytest.approx(0.2)
    there = [dataclasses.replace(st, reached=st.reached or i == 5) for i, st in enumerate(states)]
    again = summarise(plans, there, _grid(0.5), {}, PointRobot(), "red_cup", None)
    assert again.reached and again.reached_step == 5 and again.left_goal is None


def test_summary_has_one_table_with_a_header_and_a_row_per_step():
    plans = [_plan(t, 0, [1.0, 2.0]) for t in range(4)]
    s = summarise(plans, [], None, {}, PointRobot(), "red_cup", None)
    lines = s.lines()
    header = table_header(["blue_cup", "red_cup"])
    assert lines[0] == header and lines.count(header) == 1
    rows = lines[1:5]
    assert [r.split()[:3] for r in rows] == [[str(t), f"{0.2 * t:.2f}", "blue_cup"] for t in range(4)]
    assert not any(ln.startswith(("step", "   0")) for ln in s.lines(table=False))  # table left out: printed live


def test_realtime_summary_counts_time_from_the_run_start_and_names_the_step_of_the_goal():
    """Real time: messages carry wall-clock stamps and tick -1; t counts from the executor's first state
    and the goal is reached during the step whose plan was the newest at that moment."""
    t0 = 1_700_000_000.0
    plans = [_plan(-1, 0, [1.0, 2.0], stamp=t0 + 0.05 + 0.2 * k, step=k) for k in range(5)]
    states = [RobotState(stamp=t0 + 0.02 * i, tick=-1, joint_names=["a", "b", "c"], goal=0, reached=i >= 33,
                         holding=False, reason="", q=np.full(3, 0.15), qd=np.zeros(3)) for i in range(50)]
    s = summarise(plans, states, None, {}, PointRobot(), "red_cup", None)
    assert [round(e["t_s"], 2) for e in s.steps] == [0.05, 0.25, 0.45, 0.65, 0.85]
    assert s.reached and s.reached_t_s == pytest.approx(0.66) and s.reached_step == 3
    assert "goal reached: yes, during plan 3 (t = 0.66 s)" in s.lines()  # a real-time run's rows are its plans
    assert s.lines()[0].startswith("plan  t (s)")  # (it said 'step 99' of a 40-step run: its 99th plan)
    assert s.to_json()["reached_t_s"] == pytest.approx(0.66)
    assert all(str(int(t0)) not in ln for ln in s.lines())  # no raw epoch anywhere
    # a plan is stamped with the state it starts from: the one made from the reached state came after it, and one
    # made from the run's last state (a run that ends at its goal) was never executed (a review: the summary said
    # "reached during plan 89" of a run whose executor adopted 88)
    at_goal = [*plans[:3], _plan(-1, 0, [1.0, 2.0], stamp=states[33].stamp, step=3),
               _plan(-1, 0, [1.0, 2.0], stamp=states[-1].stamp, step=4)]
    s = summarise(at_goal, states, None, {}, PointRobot(), "red_cup", None)
    assert len(s.steps) == 4 and s.reached_step == 2


def test_a_real_time_summary_says_how_long_the_separation_guard_held_the_robot():
    from services.executor.config import SEPARATION_REASON

    t0 = 1_700_000_000.0
    guard = SEPARATION_REASON.format(clearance=0.1, stop_m=0.1)
    reasons = ["waiting for the first plan"] * 5 + [""] * 10 + [guard] * 25 + ["plan is 0.51 s old (limit 0.50 s)"] * 10
    states = [RobotState(stamp=t0 + 0.02 * i, tick=-1, joint_names=["a", "b", "c"], goal=0, reached=False,
                         holding=bool(r), reason=r, q=np.full(3, 0.15), qd=np.zeros(3)) for i, r in enumerate(reasons)]
    s = summarise([_plan(-1, 0, [1.0, 2.0], stamp=t0 + 0.05)], states, None, {}, PointRobot(), "red_cup", None)
    assert s.separation_held_s == pytest.approx(0.5) and s.to_json()["separation_held_s"] == pytest.approx(0.5)
    assert not s.separation_at_end  # the last states held for a stale plan
    at_end = summarise([_plan(-1, 0, [1.0, 2.0], stamp=t0 + 0.05)], states[:40], None, {}, PointRobot(), "x", None)
    assert at_end.separation_at_end and at_end.to_json()["separation_at_end"]
    assert any(ln.startswith("separation guard: held the robot 0.50 s") for ln in s.lines())
    quiet = summarise([_plan(-1, 0, [1.0, 2.0], stamp=t0 + 0.05)], states[:15], None, {}, PointRobot(), "x", None)
    assert quiet.separation_held_s == 0 and not any("separation" in ln for ln in quiet.lines())


def _posterior(tick: int, stamp: float, p: list[float]) -> ClassPosterior:
    return ClassPosterior(stamp=stamp, tick=tick, demo_id=1, index=0, class_names=["far_left", "blue_cup"],
                          posterior=np.array(p), log_likelihood=np.log(np.array(p)))


def test_each_row_shows_the_belief_its_plan_was_made_with():
    """`foresight log table` left the human (belief) column empty that the demo's table fills."""
    posts = {0: _posterior(0, 0.1, [0.7, 0.3]), 1: _posterior(1, 0.3, [0.2, 0.8])}
    s = summarise([_plan(t, 0, [1.0, 2.0]) for t in range(3)], [], None, posts, None, "blue_cup", None)
    assert [e["belief"] for e in s.steps] == ["", "far_left p=0.70", "blue_cup p=0.80"]  # the tick before's
    assert s.lines()[2].endswith("far_left p=0.70")
    realtime = summarise([_plan(-1, 0, [1.0, 2.0], stamp=t) for t in (0.05, 0.2, 0.5)], [], None,
                         {0: _posterior(-1, 0.1, [0.7, 0.3]), 1: _posterior(-1, 0.3, [0.2, 0.8])}, None, "x", None)
    assert [e["belief"] for e in realtime.steps] == ["", "far_left p=0.70", "blue_cup p=0.80"]  # the newest before
    # the end's recognition says its probability and pose: an interrupted run's differed from its last row's belief
    assert "human class: x; recognised at the end: blue_cup (p 0.80, after pose " in "\n".join(realtime.lines())
    assert realtime.to_json()["recognised_p"] == pytest.approx(0.8)


def test_a_flat_belief_names_no_class():
    """The demo's table showed "far_left p=0.13" among 8 classes (all but uniform) as though it were a belief."""
    from services.run_table import table_row
    from services.scenario import belief

    names = ["far_left", "left", "middle", "right", "far_right", "blue_cup", "red_cup", "up"]

    def post(p: list[float], classes: list[str]) -> ClassPosterior:
        return ClassPosterior(stamp=0.0, tick=0, demo_id=1, index=0, class_names=classes, posterior=np.array(p),
                              log_likelihood=np.log(np.array(p)))

    assert belief(post([0.13] + [0.87 / 7] * 7, names)) == "(flat) p=0.13"
    assert belief(post([0.26] + [0.74 / 7] * 7, names)) == "far_left p=0.26"  # over twice 1/8
    assert belief(post([0.45, 0.3, 0.25], names[:3])) == "(flat) p=0.45" and belief(post([0.5, 0.3, 0.2], names[:3])) \
        == "far_left p=0.50"
    assert belief(post([0.55, 0.45], names[:2])) == "far_left p=0.55"  # two classes: the top one always an even chance
    entry = {"step": 1, "t_s": 0.5, "chosen": "red_cup", "cost_total": {"red_cup": 1.5}, "planning_ms": 74.0}
    row = table_row(entry, ["red_cup"], belief(post([0.13] + [0.87 / 7] * 7, names)))
    assert row == table_row(entry, ["red_cup"]) + "  (flat) p=0.13"  # the columns before it as they were


def test_the_recorder_keeps_every_real_time_posterior_for_the_beliefs():
    """Real time stamps every posterior tick -1: the recorder (and the demo's live table) kept only the newest, so every
    plan but the last showed an empty belief while the person moved (a review's realtime demo: rows 1-18 empty)."""
    rec = RunRecorder()
    for msg in (_plan(-1, 0, [1.0, 2.0], stamp=0.05), _posterior(-1, 0.1, [0.7, 0.3]),
                _plan(-1, 0, [1.0, 2.0], stamp=0.2), _posterior(-1, 0.3, [0.2, 0.8]), _posterior(-1, 0.4, [0.1, 0.9]),
                _plan(-1, 0, [1.0, 2.0], stamp=0.35)):
        rec.on_message(msg)
    plans, states, grid, posts = rec.snapshot()
    s = summarise(plans, states, grid, posts, None, "x", None)
    assert [e["belief"] for e in s.steps] == ["", "far_left p=0.70", "blue_cup p=0.80"]
    lock = RunRecorder()  # lock-step: the last of each tick
    for tick, p in ((0, 0.6), (0, 0.7), (1, 0.8)):
        lock.on_message(_posterior(tick, 0.1 * tick, [p, 1 - p]))
    assert {t: float(m.posterior[0]) for t, m in lock.snapshot()[3].items()} == {0: 0.7, 1: 0.8}
    for p in (0.1, 0.2, 0.3):  # real-time ones beside them: kept apart (the arrival key was len(): 2 overwrote...)
        lock.on_message(_posterior(-1, 1.0 + p, [p, 1 - p]))
    kept = lock.snapshot()[3]
    assert sorted(float(m.posterior[0]) for m in kept.values()) == [0.1, 0.2, 0.3, 0.7, 0.8]
    assert float(kept[max(kept)].posterior[0]) == 0.3  # the newest arrival is the largest key


def test_a_restarted_planner_does_not_renumber_the_lockstep_steps():
    """A planner started again counts its own steps from 0: the rows read 6, 0, 1, ... and the switch step was
    the planner's count, not the tick."""
    plans = [_plan(t, 1 if t < 8 else 0, [2.0, 1.0] if t < 8 else [1.0, 2.0], step=t if t < 6 else t - 6)
             for t in range(10)]
    s = summarise(plans, [], None, {}, PointRobot(), "red_cup", None)
    assert [e["step"] for e in s.steps] == list(range(10))
    assert s.switch_step == 8
    realtime = [_plan(-1, 0, [1.0, 2.0], stamp=0.1 * i, step=i % 3) for i in range(5)]  # restarts twice
    assert [e["step"] for e in summarise(realtime, [], None, {}, PointRobot(), "red_cup", None).steps] == \
        list(range(5))


def test_model_for_says_when_it_trains_and_not_when_the_model_is_cached(tmp_path, monkeypatch):
    """The first `make demo` trained for a minute behind bare progress bars; now the demo says what is happening."""
    import services.predictor.train as train
    from services.scenario import model_for
    from shared.scene import load_scene

    class Trained:
        def save(self, path):
            np.savez(path, means=np.arange(4.0))

    monkeypatch.setattr(train, "train_model", lambda *a, **k: Trained())
    lib = generate_library(2, 3, seed=1)
    said: list = []
    first = model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, on_train=said.append)
    again = model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, on_train=said.append)
    assert first == again and said == [first]
    first.write_bytes(first.read_bytes()[:-30])  # a cached model cut short (a full disk, a killed copy)
    assert model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, on_train=said.append) == first
    assert said == [first, first] and np.load(first)["means"].tolist() == [0, 1, 2, 3]  # trained again: whole
    data = bytearray(first.read_bytes())
    data[data.index(b"\x93NUMPY") + 128 + 8] ^= 0xFF  # a flipped byte in the array (after its 128-byte header)
    first.write_bytes(bytes(data))
    model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, on_train=said.append)
    assert said == [first, first, first]
    np.savez_compressed(first, means=np.arange(4.0))  # the trainer's files are compressed: a member's stream can
    data = bytearray(first.read_bytes())  # be damaged beyond its CRC (zlib's own error, which escaped as a traceback)
    name_len, extra_len = int.from_bytes(data[26:28], "little"), int.from_bytes(data[28:30], "little")
    data[30 + name_len + extra_len] = 0xFF  # the first deflate block's type: 11, invalid
    first.write_bytes(bytes(data))
    model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, on_train=said.append)
    assert said == [first] * 4


def test_the_demo_s_model_for_keypoints_is_trained_for_the_tracker_and_cached_apart(tmp_path, monkeypatch):
    """`foresight demo --human keypoints --keypoint-noise-m 0.02`: its model's novelty threshold is calibrated for the
    noise (a model calibrated as recorded called 63 of 72 poses of a known reach unfamiliar), and with keypoints its
    time starts where the tracker's reach rule starts a demonstration (a review: the tracker's indices were 8-30
    samples behind the library's), each cached under another key; the replayer's model keeps its key (TrainConfig's
    repr as before) whatever the keypoints' noise."""
    import services.predictor.train as train
    from services.demo import DemoConfig
    from services.demo_run import prepare_inputs
    from shared.scene import load_scene

    noises: list = []

    class Trained:
        def save(self, path):
            np.savez(path, means=np.arange(4.0))

    def fake(library, scene, cfg, **kwargs):
        noises.append((cfg.sensor_noise_m, cfg.time_from))
        return Trained()

    monkeypatch.setattr(train, "train_model", fake)
    (tmp_path / "models").mkdir()  # as the demo's checks leave it
    paths = []
    for human, noise in (("replayer", 0.0), ("keypoints", 0.0), ("keypoints", 0.02), ("replayer", 0.02)):
        cfg = DemoConfig(human=human, keypoint_noise_m=noise, models_dir=tmp_path / "models", mode="realtime")
        paths.append(prepare_inputs(cfg, load_scene(), tmp_path / f"run-{human}-{noise}", lambda line: None)[1])
    assert paths[0] == paths[3] and len({paths[0], paths[1], paths[2]}) == 3
    assert noises == [(0.0, "recording"), (0.0, "tracker"), (0.02, "tracker")]


def test_a_run_scored_against_a_final_grid_that_is_no_prediction_says_so() -> None:
    """A lone `foresight demo --method current` scored its interference against its own final current-occupancy grid
    and labelled it 'final prediction'."""
    from services.scenario import Summary, final_label
    from shared.protocol import OccupancyGrid

    def grid(method: str) -> OccupancyGrid:
        return OccupancyGrid.from_dense(np.zeros((2, 2, 2), np.float32), [0.0, 0.0, 0.0], 0.05, stamp=0.0, tick=0,
                                        demo_id=0, index=0, method=method, tick_last=True)

    assert [final_label(None), final_label(grid("prediction")), final_label(grid("current"))] == [
        "final prediction", "final prediction", "final current occupancy"]
    summary = Summary([], [], None, 1.5, None, False, None, "blue_cup", None,
                      scored_against=final_label(grid("current")))
    assert "interference cost of the executed trajectory (final current occupancy): 1.5000" in summary.lines()


def test_the_final_grid_of_a_real_time_stream_is_the_newest_demonstrations():
    """Real time stamps every grid tick -1 and a pose's index restarts with each demonstration: the sample order
    alone kept the first demonstration's last grid (index 50) over the second's (index 3)."""
    rec = RunRecorder()
    dims = (4, 4, 4)
    for stamp, demo, index in ((1.0, 0, 50), (2.0, 1, 3)):
        rec.on_message(OccupancyGrid.from_dense(np.zeros(dims, np.float32), (0.0, 0.0, 0.0), 0.05, stamp=stamp,
                                                tick=-1, tick_last=True, demo_id=demo, index=index,
                                                method="prediction"))
    final = rec.snapshot()[2]
    assert final is not None and (final.demo_id, final.index) == (1, 3)


def test_a_model_save_interrupted_at_its_rename_leaves_no_temporary_file_and_the_old_model(tmp_path, monkeypatch):
    """Ctrl-C between model_for's save and its rename left demo-*.PID.tmp.npz in the models directory."""
    import services.predictor.train as train
    from services.scenario import model_for
    from shared.scene import load_scene

    class Trained:
        def save(self, path):  # as PredictionModel.save: written whole under a temporary name
            with atomic_write(path) as f:
                np.savez(f, means=np.arange(4.0))

    monkeypatch.setattr(train, "train_model", lambda *a, **k: Trained())
    lib = generate_library(2, 3, seed=1)
    first = model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, progress=False)
    first.write_bytes(b"damaged")  # trained again on the next call
    real = os.replace

    def interrupted(src, dst, *a, **k):
        if os.fspath(dst) == os.fspath(first):
            raise KeyboardInterrupt
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        model_for(lib, load_scene(), lib.demos[0], tmp_path, components=2, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [first.name] and first.read_bytes() == b"damaged"


def test_a_goal_reached_after_the_last_step_is_said_so_not_during_a_step_the_table_lacks():
    """A 10-step run said "goal reached: yes, during step 20" under a table of steps 0..9: the tick counts on while
    the robot finishes its last plan."""
    plans = [_plan(i, 0, [1.0, 3.0]) for i in range(4)]
    states = [RobotState(stamp=0.1 * i, tick=i, joint_names=["a", "b", "c"], goal=0, reached=i == 7, holding=False,
                         reason="", q=np.full(3, 0.15), qd=np.zeros(3)) for i in range(8)]
    s = summarise(plans, states, _grid(0.5), {}, PointRobot(), "red_cup", None)
    assert s.reached and s.reached_step == 7 and [e["step"] for e in s.steps] == [0, 1, 2, 3]
    text = "\n".join(s.lines())
    assert "goal reached: yes, after the last step (3), at t = 0.70 s" in text and "during step 7" not in text


def test_the_summary_names_no_class_recognised_at_the_end_when_the_last_posterior_is_flat():
    """The step table said "(flat) p=0.13" for the last belief and the summary's line under it "recognised at the
    end: far_left": one rule (shared.belief) for both."""
    names = ["far_left", "blue_cup", "red_cup", "near_left", "near_centre", "near_right", "far_right", "right_edge"]
    plans = [_plan(i, 0, [1.0, 3.0]) for i in range(2)]
    states = [RobotState(stamp=0.1 * i, tick=i, joint_names=["a", "b", "c"], goal=0, reached=False, holding=False,
                         reason="", q=np.full(3, 0.15), qd=np.zeros(3)) for i in range(2)]

    def lines(p: list[float]) -> str:
        post = ClassPosterior(stamp=0.0, tick=1, demo_id=1, index=5, class_names=names, posterior=np.array(p),
                              log_likelihood=np.log(np.array(p)))
        return "\n".join(summarise(plans, states, _grid(0.5), {1: post}, PointRobot(), "red_cup", None).lines())

    assert "recognised at the end: none (flat; most probable far_left) (p 0.13" in lines([0.13] + [0.87 / 7] * 7)
    assert "recognised at the end: far_left (p 0.30" in lines([0.30] + [0.70 / 7] * 7)


def test_realtime_summary_keeps_the_plans_the_executor_adopted() -> None:
    """With the plans' arrival times the steps are the plans the executor took (services.adopted_plans): plan 1 is
    overtaken by plan 2 before the next state, plan 3 came after the last; all were stamped before the last state."""
    t0 = 100.0
    states = [RobotState(stamp=t0 + t, tick=-1, joint_names=["a", "b", "c"], goal=0, reached=False, holding=False,
                         reason="", q=np.zeros(3), qd=np.zeros(3)) for t in (0.0, 0.02, 0.04)]
    plans = [_plan(-1, 0, [1.0, 2.0], stamp=t0 + t, step=k) for k, t in enumerate((0.0, 0.02, 0.02, 0.03))]
    s = summarise(plans, states, None, {}, PointRobot(), "red_cup", None,
                  received=[t0 + t for t in (0.01, 0.03, 0.035, 0.05)])
    assert [e["step"] for e in s.steps] == [0, 2]
    assert s.to_json()["reached_after_last_step"] is False


def test_the_model_cache_key_tells_libraries_of_other_features_apart() -> None:
    """A 17-column CSV and a wide .npz of the same numbers shared a cached model; the paper's 12 keep their key."""
    from services.scenario import _library_digest

    lib = generate_library(2, 2, seed=0)
    renamed = dataclasses.replace(lib, feature_names=tuple(f"f{i}" for i in range(lib.n_features)))
    assert _library_digest(renamed) != _library_digest(lib)
    assert _library_digest(lib) == _library_digest(generate_library(2, 2, seed=0))
