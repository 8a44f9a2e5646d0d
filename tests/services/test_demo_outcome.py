"""The demo's measured outcome (interference, contact with the real human) and its verdict in words."""

from __future__ import annotations

import types
from pathlib import Path

import numpy as np
import pytest
import torch

from services import demo_outcome
from services.demo_outcome import Outcome, measure_run, outcome_lines, verdict
from shared.protocol import HumanPose, OccupancyGrid, RobotState
from shared.robot import PR2
from shared.scene import load_scene


def _outcome(name: str, interference: float, contact: float, near: float, clearance: float) -> Outcome:
    t = np.linspace(0.0, 1.0, 5)
    return Outcome(name, interference, contact, near, clearance, None, None, ["red_cup"] * 3, t, np.zeros((5, 3)),
                   np.full(5, clearance))


def test_verdict_by_contact_when_anyone_touched() -> None:
    shown = [_outcome("prediction", 0.1, 0.0, 0.2, 0.03), _outcome("current occupancy", 5.0, 1.5, 2.0, -0.02),
             _outcome("no human cost", 9.0, 2.5, 3.0, -0.05)]
    assert verdict(shown).startswith("shown, against current occupancy and no human cost")
    assert "touched the real human 0.0 s against 1.5 s, 2.5 s" in verdict(shown)
    worse = [_outcome("prediction", 0.1, 2.0, 2.0, -0.03), *shown[1:]]
    text = verdict(worse)
    assert text.startswith("not shown in this run (it did not stay further from the human)")
    assert "Across the robot's pace" in text
    higher = [_outcome("prediction", 6.0, 0.0, 0.0, 0.1), *shown[1:]]
    assert verdict(higher).startswith("not shown in this run (its interference was not the lowest)")


def test_a_run_cut_short_gets_no_verdict_and_is_marked_in_the_table() -> None:
    """Ctrl-C in the second planner's run of --compare: a 9-step run was judged against a 20-step one, 'shown'."""
    import dataclasses

    runs = [_outcome("prediction", 0.55, 0.0, 0.0, 0.128), _outcome("current occupancy", 19.0, 0.0, 1.9, 0.019)]
    runs[1] = dataclasses.replace(runs[1], cut_short="interrupted after 9 of 20 steps")
    text = verdict(runs)
    assert text.startswith("none: the current occupancy run was interrupted after 9 of 20 steps")
    lines = outcome_lines(runs)
    assert any(ln.startswith("  current occupancy *") for ln in lines)
    assert "  * current occupancy: interrupted after 9 of 20 steps" in lines
    assert f"verdict: {text}" in lines and not any("shown" in ln for ln in lines)
    # one interrupted run: no advice to run the whole comparison (a review found it printed after Ctrl-C)
    lines = outcome_lines(runs[1:])
    assert lines[-1] == "  * current occupancy: interrupted after 9 of 20 steps" and "--compare" not in "".join(lines)


def test_verdict_on_a_contact_tie_with_one_baseline_goes_by_nearness() -> None:
    # the demo's Table I situation: the current-occupancy planner does not touch the human either, but comes closer
    runs = [_outcome("prediction", 0.55, 0.0, 0.0, 0.128), _outcome("current occupancy", 20.0, 0.0, 2.1, 0.019),
            _outcome("no human cost", 60.5, 2.2, 3.4, -0.049)]
    text = verdict(runs)
    assert text.startswith("shown, against current occupancy and no human cost")
    assert "touched the real human 0.0 s against 0.0 s, 2.2 s" in text
    assert "(current occupancy did not touch the human either: there the time within 5 cm" in text  # was "as long as"
    both = [_outcome("prediction", 0.55, 0.5, 0.6, -0.01), _outcome("current occupancy", 20.0, 0.5, 2.1, -0.02)]
    assert "current occupancy touched the human as long as the prediction planner" in verdict(both)
    assert "closest 13 cm against 2 cm, -5 cm" in text
    nearer = [_outcome("prediction", 0.55, 0.0, 2.5, 0.01), *runs[1:]]  # a tie, and nearer than that baseline
    assert verdict(nearer).startswith("not shown in this run (it did not stay further from the human)")


def test_verdict_by_clearance_when_nobody_touched_says_so() -> None:
    runs = [_outcome("prediction", 0.01, 0.0, 0.0, 0.13), _outcome("current occupancy", 7.9, 0.0, 3.7, 0.01),
            _outcome("no human cost", 9.9, 0.0, 4.7, 0.01)]
    text = verdict(runs)
    assert text.startswith("shown") and "no planner touched the real human" in text
    assert "within 5 cm of it 0.0 s against 3.7 s, 4.7 s; closest 13 cm against 1 cm, 1 cm" in text
    assert verdict(runs[:1]) == ""  # one planner: nothing to compare
    lines = outcome_lines(runs)
    assert lines[-1] == f"verdict: {text}"
    assert [ln.split()[0] for ln in lines[3:6]] == ["prediction", "current", "no"]
    # one row alone said nothing of what prediction changes: it says where the comparison is
    assert "foresight demo --compare" in outcome_lines(runs[:1])[-1]



def test_a_compare_run_interrupted_before_the_other_planners_says_so() -> None:
    """Ctrl-C while the second planner's run started: the table held the first alone and advised running
    `foresight demo --compare`, to a --compare run; the picture's title did not say (a new user's run)."""
    from services.demo_outcome import cut_words

    first = [_outcome("prediction", 0.01, 0.0, 0.0, 0.13)]
    planned = ["prediction", "current occupancy", "no human cost"]
    lines = outcome_lines(first, planned=planned)
    assert lines[-1] == "not compared: the run was interrupted before current occupancy and no human cost ran"
    assert "--compare" not in "".join(lines)
    assert cut_words(first, planned) == "current occupancy and no human cost not run (interrupted)"
    assert cut_words(first, ["prediction"]) == "" and "foresight demo --compare" in outcome_lines(first, planned=[
        "prediction"])[-1]  # a single run: the advice stands
    # a service of the second planner's run died at start: that was called an interruption
    assert outcome_lines(first, planned=planned, failed=True)[-1] == (
        "not compared: current occupancy and no human cost did not run to an outcome (a service failed: see the lines "
        "above)")
    assert cut_words(first, planned, failed=True) == "current occupancy and no human cost not run (a service failed)"


def test_measure_run_scores_contact_and_interference() -> None:
    scene = load_scene("pr2_two_cups_side")
    robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    q0 = robot.q_start.numpy().astype(np.float64)
    states = [RobotState(stamp=0.5 * i, tick=i, joint_names=robot.joint_names, goal=0, reached=False, holding=False,
                         reason="", q=q0, qd=np.zeros(len(q0))) for i in (2, 0, 1)]  # any order
    summary = types.SimpleNamespace(extra={}, switch_step=None, reached_step=None, chosen_goal_per_step=["red_cup"] * 3,
                                    mcap_path=None, unit="step", steps=[], reached_t_s=None)
    # no human, empty prediction: nothing measured against
    empty = OccupancyGrid.from_dense(np.zeros(scene.grid.dims), scene.grid.origin, scene.grid.resolution, stamp=0.0,
                                     tick=0, tick_last=True, demo_id=0, index=0, method="prediction")
    o = measure_run("prediction", states, [], empty, robot, scene, summary)
    assert o.interference == 0.0 and o.contact_s == 0.0 and not np.isfinite(o.min_clearance_m)
    assert list(o.stamps) == [0.0, 0.5, 1.0] and o.ee_path.shape == (3, 3)
    # the whole grid occupied: the robot is inside the prediction the whole second
    full = OccupancyGrid.from_dense(np.ones(scene.grid.dims), scene.grid.origin, scene.grid.resolution, stamp=0.0,
                                    tick=0, tick_last=True, demo_id=0, index=0, method="prediction")
    assert measure_run("prediction", states, [], full, robot, scene, summary).interference > 0.0
    # a human: its clearance is measured at every state
    pose = HumanPose(stamp=0.0, tick=0, tick_last=True, demo_id=1, index=0,
                     features=np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5]))
    with_human = measure_run("prediction", states, [pose], None, robot, scene, summary)
    assert with_human.clearance.shape == (3,) and np.isfinite(with_human.min_clearance_m)
    assert with_human.contact_s == pytest.approx(1.0 if with_human.min_clearance_m <= 0 else 0.0)


def test_on_a_contact_tie_time_near_decides_before_clearance() -> None:
    """1 mm more clearance used to outweigh 12x the time within 5 cm ('shown' for the planner that stayed near)."""
    near_long = [_outcome("prediction", 0.1, 0.0, 6.0, 0.031), _outcome("current occupancy", 0.2, 0.0, 0.5, 0.030),
                 _outcome("no human cost", 0.3, 0.0, 0.5, 0.030)]
    assert verdict(near_long).startswith("not shown in this run (it did not stay further from the human)")
    same_time = [_outcome("prediction", 0.1, 0.0, 0.0, 0.12), _outcome("current occupancy", 0.2, 0.0, 0.0, 0.08),
                 _outcome("no human cost", 0.3, 0.0, 0.0, 0.05)]
    assert verdict(same_time).startswith("shown")  # neither came within 5 cm: the closest approach decides


def test_compare_interrupted_before_a_later_planners_first_plan_keeps_the_finished_runs(tmp_path, monkeypatch) -> None:
    """Ctrl-C while the second planner's services started threw the first run's table and picture away."""
    import threading

    import services.demo as demo
    import services.demo_run as demo_run
    from services.demo_run import RunRecord
    from services.scenario import Summary

    calls = []

    def run_once(cfg, name, stop, out, started=None):
        calls.append(name)
        if name == "prediction":
            s = Summary(steps=[], chosen_goal_per_step=["red_cup"], switch_step=None, interference_cost=0.0,
                        mcap_path=str(tmp_path / "x.mcap"), reached=True, reached_step=3, human_class="blue_cup",
                        recognised_class="blue_cup", goal_names=["red_cup"])
            return 0, RunRecord(name, s, [], None, [], tmp_path)
        return 130, None  # interrupted before its first plan

    monkeypatch.setattr(demo_run, "run_once", run_once)
    status, summary = demo.run_demo(demo.DemoConfig(compare=True, run_dir=tmp_path / "runs"), threading.Event(),
                                    out=lambda line: None)
    assert calls == ["prediction", "current occupancy"] and status == 130
    assert summary is not None and [row["planner"] for row in summary.extra["comparison"]] == ["prediction"]
    assert "verdict" not in summary.extra and Path(summary.extra["figure"]).is_file()


def test_compare_stops_after_a_planner_whose_teardown_was_interrupted(tmp_path, monkeypatch) -> None:
    """Ctrl-C while the first planner's services stopped (its run whole, status 0): the demo said "nothing was lost"
    and went on to start the next planner with the stop already set (a review's script)."""
    import threading

    import services.demo as demo
    import services.demo_run as demo_run
    from services.demo_run import RunRecord
    from services.scenario import Summary

    stop, calls, said = threading.Event(), [], []

    def run_once(cfg, name, stop_, out, started=None):
        calls.append(name)
        stop.set()  # the signal came while this run's services stopped
        s = Summary(steps=[], chosen_goal_per_step=["red_cup"], switch_step=None, interference_cost=0.0,
                    mcap_path=str(tmp_path / "x.mcap"), reached=True, reached_step=3, human_class="blue_cup",
                    recognised_class="blue_cup", goal_names=["red_cup"])
        return 0, RunRecord(name, s, [], None, [], tmp_path)

    monkeypatch.setattr(demo_run, "run_once", run_once)
    status, summary = demo.run_demo(demo.DemoConfig(compare=True, run_dir=tmp_path / "runs"), stop, out=said.append)
    assert calls == ["prediction"] and status == 130
    assert "foresight demo: interrupted: the comparison stops after prediction" in said
    assert summary is not None and "verdict" not in summary.extra


def test_an_interference_tie_is_no_loss_and_the_verdict_says_so() -> None:
    """A real-time --compare: 0.000 against 0.000 (neither path entered the final prediction's volume), the
    prediction planner 11 cm from the person and never within 5 cm, the baselines 4 and 3 cm: "not shown (its
    interference was not the lowest)"."""
    runs = [_outcome("prediction", 0.0, 0.0, 0.0, 0.107), _outcome("current occupancy", 0.0, 0.0, 0.68, 0.040),
            _outcome("no human cost", 24.13, 0.0, 1.14, 0.032)]
    text = verdict(runs)
    assert text.startswith("shown, against current occupancy and no human cost"), text
    assert "(current occupancy interfered with the predicted motion as little: the nearness" in text
    nearer = [_outcome("prediction", 0.0, 0.0, 0.9, 0.02), *runs[1:]]  # a tie, and nearer: still not shown
    assert verdict(nearer).startswith("not shown in this run (it did not stay further from the human)")
    higher = [_outcome("prediction", 0.5, 0.0, 0.0, 0.107), *runs[1:]]  # more than 0.0 is no tie
    assert verdict(higher).startswith("not shown in this run (its interference was not the lowest)")


def test_interferences_the_verdict_prints_alike_are_a_tie() -> None:
    """A real-time --compare printed 0.001 / 0.001 / 0.000 and "not shown in this run (its interference was not the
    lowest): interference with the predicted motion 0.00 against 0.00, 0.00"; the prediction planner 10 cm from the
    person, never within 5 cm, the baselines 7 and 4 cm, the last 0.5 s within 5 cm."""
    runs = [_outcome("prediction", 0.0011, 0.0, 0.0, 0.099), _outcome("current occupancy", 0.0009, 0.0, 0.0, 0.072),
            _outcome("no human cost", 0.0002, 0.0, 0.54, 0.043)]
    text = verdict(runs)
    assert text.startswith("shown, against current occupancy and no human cost"), text
    assert "(current occupancy and no human cost interfered with the predicted motion as little" in text
    more = [_outcome("prediction", 0.0102, 0.0, 0.0, 0.099), *runs[1:]]  # 0.01 against 0.00: no tie
    assert verdict(more).startswith("not shown in this run (its interference was not the lowest)")


def test_the_summary_counts_the_poses_the_novelty_test_called_unlike_every_class(tmp_path) -> None:
    """A real-time run with 2 cm of keypoint noise: the predictor warned "unlike every class" for 63 of 72 poses of a
    known blue_cup reach, and the summary said only "recognised at the end: blue_cup (p 0.96)" (a review)."""
    import dataclasses

    from services.demo_outcome import novelty_counts
    from shared.protocol import ClassPosterior, Keys, encode
    from shared.recording.writer import McapLog

    keys, path = Keys(), tmp_path / "run.mcap"
    log = McapLog(path, keys, viz_thread=False)
    for i, familiar in enumerate([True, True, False, False, False]):
        msg = ClassPosterior(stamp=float(i), tick=-1, demo_id=1, index=i, class_names=["blue_cup", "red_cup"],
                             posterior=np.array([0.9, 0.1]), log_likelihood=np.array([-1.0, -3.0]), familiar=familiar,
                             familiarity=5.0 if familiar else -40.0)
        assert log.on_sample(keys.posterior, encode(msg)) is not None
    log.close()
    assert novelty_counts(str(path)) == (3, 5)
    assert novelty_counts(None) == (0, 0) and novelty_counts(str(tmp_path / "missing.mcap")) == (0, 0)
    one = dataclasses.replace(_outcome("prediction", 0.3, 0.0, 0.0, 0.1), unfamiliar=3, judged=5)
    lines = outcome_lines([one])
    assert lines[0].startswith("novelty: the predictor called 3 of 5 poses unlike every class"), lines
    assert one.to_json()["unfamiliar_poses"] == 3 and one.to_json()["poses_judged"] == 5
    both = outcome_lines([one, _outcome("current occupancy", 0.3, 0.0, 0.0, 0.1)])
    assert [ln[:26] for ln in both if ln.startswith("novelty")] == ["novelty (prediction run): "]
    assert not any(ln.startswith("novelty") for ln in outcome_lines([_outcome("prediction", 0.3, 0.0, 0.0, 0.1)]))
    # measure_run reads the counts from the run's log
    scene = load_scene("pr2_two_cups_side")
    robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    summary = types.SimpleNamespace(extra={}, switch_step=None, reached_step=None, chosen_goal_per_step=[],
                                    mcap_path=str(path), unit="plan", steps=[], reached_t_s=None)
    o = measure_run("prediction", [], [], None, robot, scene, summary)
    assert (o.unfamiliar, o.judged) == (3, 5)


def test_a_goal_reached_after_the_last_step_is_said_by_its_time_not_a_step_past_the_run() -> None:
    """Lock-step's tick counts on while the robot ends its last plan: the table said "reached step 22" of 20 steps."""
    import dataclasses

    o = dataclasses.replace(_outcome("prediction", 0.3, 0.0, 0.0, 0.1), reached_step=22, reached_t_s=11.2,
                            reached_after=True)
    row = outcome_lines([o])[3]
    assert row.rstrip().endswith("after (11.2 s)") and "22" not in row
    assert o.to_json()["reached_step"] == 22 and o.to_json()["reached_after_last_step"] is True
    steps = [{"step": k, "t_s": 0.5 * k} for k in range(20)]
    summary = types.SimpleNamespace(steps=steps, reached_step=22)
    assert demo_outcome.reached_after_last(summary)
    assert not demo_outcome.reached_after_last(types.SimpleNamespace(steps=steps, reached_step=19))
