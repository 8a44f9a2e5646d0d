"""One lock-step run of the four services in-process, and the experiment commands on a small budget."""

from __future__ import annotations

import dataclasses
import json
import math
import re
import time
import types

import numpy as np
import pytest

import services.experiments.harness as harness
from services.experiments.cli import main
from services.experiments.harness import LateInputs, PlanningFailed, RunSpec, ServiceFailed, _Collector, run_lockstep
from services.experiments.heldout import HeldOutModels, human_file, samples_per_tick
from services.experiments.planners import Timing, build_planner
from services.planner.core import PlannerError
from shared.scene import load_scene
from shared.synthetic import generate_library


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("harness")
    scene = load_scene("pr2_two_cups_side")
    lib = generate_library(8, 4, seed=4, scene=scene)
    demo = lib.by_class(0)[0]
    model = HeldOutModels(lib, scene, root, components=2).without([demo])
    timing = Timing(steps=4, iterations=5)
    planner = build_planner(scene, ["red_cup"], True, timing, compile=False)
    spec = RunSpec(scene, model, human_file(lib, demo, root), samples_per_tick(demo, timing.steps), steps=timing.steps,
                   period_s=timing.period_s, seed=3)
    return spec, planner


@pytest.fixture(scope="module")
def models_dir(tmp_path_factory):
    """One held-out model cache for the command tests: models are cached by content (library, held-out set, scene,
    options), so the commands that need the same model train it once."""
    return tmp_path_factory.mktemp("models")


def test_a_run_goes_through_every_service_and_is_reproducible(small_run):
    spec, planner = small_run
    a = run_lockstep(spec, planner)
    b = run_lockstep(spec, planner)
    assert [p.tick for p in a.plans] == list(range(4))
    assert a.result is not None and a.result.steps == 4
    assert len(a.poses) > 0 and a.final_occupancy is not None and a.posteriors
    assert a.plans[0].goal_names == ["red_cup"]
    np.testing.assert_array_equal(a.q(), b.q())
    for pa, pb in zip(a.plans, b.plans, strict=True):
        np.testing.assert_array_equal(pa.trajectories, pb.trajectories)


def test_interference_command_prints_the_table_i_json(tmp_path, capsys, models_dir):
    args = ["interference", "--demos", "1", "--seeds", "1", "--steps", "3", "--iterations", "3", "--components", "2",
            "--no-compile", "--models-dir", str(models_dir), "--work-dir", str(tmp_path / "w"), "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    for key in ("basic", "least_penetration", "current"):
        # one demonstration, one seed: its mean is that run's score, and the table's measures are the run's
        (run,) = [r for r in data["runs"] if r["planner"] == key]
        assert data[key] == [pytest.approx(run["interference"])] and run["interference"] >= 0
        assert data["min_clearance"][key] == [pytest.approx(run["min_clearance"])]
        assert data["time_in_contact"][key] == [pytest.approx(run["time_in_contact"])]
    basic, least = data["basic"][0], data["least_penetration"][0]
    ratio = data["ratio_basic_over_least_penetration"]
    assert ratio == pytest.approx(basic / least) if least > 0 else not math.isfinite(ratio)
    assert data["scene"] == "pr2_two_cups_side" and data["human_class"] == "blue_cup"
    assert set(data["min_clearance"]) == {"basic", "least_penetration", "current"}


def test_switch_command_prints_the_settle_steps_and_draws_fig9(tmp_path, capsys, models_dir):
    png = tmp_path / "fig9.png"
    args = ["switch", "--demos", "1", "--steps", "3", "--iterations", "3", "--components", "2", "--no-compile",
            "--models-dir", str(models_dir), "--work-dir", str(tmp_path / "w"), "--plot", str(png), "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["switch_steps_prediction"]) == len(data["switch_steps_current"]) == 1
    for method in ("prediction", "current"):
        # the settle step is read off the run's chosen goals (the first step from which it keeps its last goal)
        (run,) = [r for r in data["runs"] if r["method"] == method]
        goals = run["goals"]
        assert len(goals) == 3 and run["final_goal"] == goals[-1]
        settle = next(i for i in range(len(goals)) if all(g == goals[-1] for g in goals[i:]))
        assert data[f"switch_steps_{method}"] == [settle] and data[f"switch_step_{method}"] == float(settle)
    assert png.is_file() and png.stat().st_size > 10_000


@pytest.mark.parametrize(("args", "named"), [(["interference", "--steps", "0"], "--steps"),
                                             (["switch", "--scene", "nowhere"], "nowhere"),
                                             (["interference", "--library", "/no/such/library"], "/no/such/library"),
                                             (["switch", "--human-cup", "green_cup"], "green_cup"),
                                             (["interference", "--trials", "authors"], "--trials authors"),
                                             (["pace", "--product-paces", "0.5,2"], "--product-paces")])
def test_bad_options_give_one_line(args, named, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(args)
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0]


def test_a_paper_protocol_run_paces_the_path_and_executes_the_rest_after_the_last_step(small_run):
    from services.experiments.protocol import PAPER, move3d_path_weights, run_pacing

    spec, _ = small_run
    planner = build_planner(spec.scene, ["red_cup"], True, Timing(steps=4, iterations=3), compile=False,
                            protocol=PAPER)
    assert planner.stomp.config.rollouts == 10 and planner.stomp.config.reuse == 5
    assert planner.config.stomp.waypoints == 101 and planner.config.goal_choice == "human"
    weights = move3d_path_weights(planner.robot)
    pacing = run_pacing(PAPER, spec.scene.name, weights)
    assert pacing["path_per_step"] == pytest.approx(0.05) and pacing["finish_path"]
    rec = run_lockstep(dataclasses.replace(spec, **pacing), planner)
    assert [p.tick for p in rec.plans] == list(range(4))  # replanned in the 4 steps only
    q = rec.q()
    ticks = np.array([s.tick for s in rec.states])
    length = np.linalg.norm(np.diff(q, axis=0) * weights, axis=1)
    per_step = [length[ticks[1:] == n].sum() for n in range(ticks.max() + 1)]
    assert per_step[0] == 0.0  # the first plan is executed from step 1 on (Fig. 4)
    # the authors' side-scene pace, on the wire (chords across a waypoint are a little shorter than the path)
    np.testing.assert_allclose(per_step[1:4], 0.05, rtol=1e-3)
    assert rec.result.finish_steps == ticks.max() - 3 > 0  # then the rest of the path, without a new plan
    np.testing.assert_allclose(q[-1], rec.plans[-1].trajectories[rec.plans[-1].chosen, -1], atol=1e-5)
    assert rec.result.reached and rec.result.reached_step > 3
    again = run_lockstep(dataclasses.replace(spec, **pacing), planner)  # lock-step and seeded: the same run
    np.testing.assert_array_equal(again.q(), q)


def test_paper_protocol_commands_run_in_the_authors_scene_and_measure_along_the_path(tmp_path, capsys, models_dir):
    small = ["--steps", "2", "--iterations", "2", "--components", "2", "--no-compile", "--models-dir",
             str(models_dir), "--work-dir", str(tmp_path / "w"), "--json"]
    assert main(["interference", "--protocol", "paper", "--demos", "1", "--seeds", "1", *small]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["protocol"] == "paper" and data["scene"] == "pr2_two_cups_side_parallel"
    assert data["authors_comparison"] == []  # the synthetic library: not the authors' motions
    assert all(r["reached_step"] is not None and r["reached_step"] >= 2 for r in data["runs"])  # the rest, executed
    png = tmp_path / "fig9.png"
    assert main(["switch", "--protocol", "paper", "--demos", "1", "--plot", str(png), *small]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["protocol"] == "paper" and png.is_file() and png.stat().st_size > 10_000


def test_pace_command_prints_a_point_per_protocol_library_and_pace(tmp_path, capsys, models_dir):
    png = tmp_path / "pace.png"
    args = ["pace", "--product-paces", "0.25,0.5", "--paper-paces", "0.05,0.1", "--demos", "1", "--seeds", "1",
            "--iterations", "3",
            "--components", "2", "--no-compile", "--models-dir", str(models_dir), "--work-dir",
            str(tmp_path / "w"), "--plot", str(png), "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert [(p["protocol"], p["pace"]) for p in data["points"]] == [("product", 0.25), ("product", 0.5),
                                                                     ("paper", 0.05), ("paper", 0.1)]
    for p in data["points"]:
        assert p["library"] == "synthetic"
        basic, least = p["basic"]["interference"], p["least_penetration"]["interference"]
        if least > 0:  # Table I's ratio of the point's own means; inf where least penetration scores 0, else nan
            assert p["ratio"] == pytest.approx(basic / least)
        else:
            assert math.isinf(p["ratio"]) if basic > 0 else math.isnan(p["ratio"])
        for name in ("basic", "least_penetration"):
            assert set(p[name]) >= {"contact_s", "min_clearance_m", "reached_step"}
    assert data["operating_point"]["paper"] == pytest.approx(0.05)
    assert png.is_file() and png.stat().st_size > 10_000


def test_a_run_whose_planner_fails_a_step_fails_at_once_naming_why(small_run, monkeypatch):
    spec, planner = small_run

    def fail(*args, **kwargs):
        raise PlannerError("no reachable goal: red_cup: outside the limits")

    monkeypatch.setattr(planner, "step", fail)  # the executor would wait lockstep_timeout_s (60 s) per tick
    started = time.monotonic()
    with pytest.raises(PlanningFailed, match=r"failed 1 step\(s\) of the run \(0 planned\); last: no reachable goal"):
        run_lockstep(spec, planner)
    assert time.monotonic() - started < 30


def test_a_run_whose_last_messages_never_come_is_measured_with_a_warning_naming_what_is_missing(caplog):
    collect = _Collector()
    result = types.SimpleNamespace(times=np.zeros(3))  # the executor published 3 states; none came
    started = time.monotonic()
    with caplog.at_level("WARNING", logger="foresight.experiments"):
        collect.settle(result, quiet_s=0.02, limit_s=0.2)
    assert time.monotonic() - started < 5
    assert "not all in after 0.2 s (0 of 3 robot states)" in caplog.text


def test_a_service_that_dies_fails_the_run_at_once_with_its_error(small_run, monkeypatch):
    """A torch error in the planner thread was seen by nobody: the executor waited 60 s per tick and the run ended
    in 'executor did not stop within 300 s', its cause neither chained nor logged."""
    spec, planner = small_run
    step = planner.step

    def dies(*args, **kwargs):
        if planner.step_index == 1:
            raise RuntimeError("CUDA error: an illegal memory access (injected)")
        return step(*args, **kwargs)

    monkeypatch.setattr(planner, "step", dies)
    started = time.monotonic()
    with pytest.raises(ServiceFailed, match="the planner failed during the run: RuntimeError: CUDA error") as exc:
        run_lockstep(spec, planner)
    assert isinstance(exc.value.__cause__, RuntimeError) and time.monotonic() - started < 30


def test_a_late_prediction_refuses_the_run_instead_of_scoring_another_path(small_run, monkeypatch):
    """A grid late past the lock-step waits gave another path (the planner used the grid before), scored as if it
    were the reproducible run."""
    from services.predictor.service import PredictorService

    spec, planner = small_run
    for name in ("ExecutorConfig", "PlannerServiceConfig"):  # the waits at 1 s instead of 60 s
        cls = getattr(harness, name)
        monkeypatch.setattr(harness, name, lambda *a, _cls=cls, **k: _cls(*a, **{
            f: (1.0 if f in ("lockstep_timeout_s", "input_timeout_s") else v) for f, v in k.items()}))
    process = PredictorService._process

    def late(self, msg, grid, now):
        if getattr(msg, "tick", -1) == 1 and getattr(msg, "tick_last", False):
            time.sleep(1.5)
        return process(self, msg, grid, now)

    monkeypatch.setattr(PredictorService, "_process", late)
    # which side's wait runs out first depends on the machine's load: the executor's (for the late grid) always,
    # the planner's (for the same grid, at tick 2) when the grid is later than both waits together
    with pytest.raises(LateInputs) as late:
        run_lockstep(spec, planner)
    counts = re.search(r"without a plan or prediction (\d+) time\(s\), the planner planned (\d+) tick\(s\)",
                       str(late.value))
    assert counts and int(counts[1]) + int(counts[2]) >= 1, str(late.value)


def test_a_period_longer_than_the_stale_limit_still_moves_the_robot(small_run):
    """At --period-s 0.6 every plan was 0.6 s old when it started, over the executor's 0.5 s: every step held and
    the commands scored a robot that never moved as 0 interference."""
    spec, planner = small_run
    rec = run_lockstep(dataclasses.replace(spec, period_s=0.6), planner)
    assert rec.result.held_steps == 1  # the first step only: no plan yet
    assert np.abs(np.diff(rec.q(), axis=0)).sum() > 0.1


def test_the_executor_models_are_kept_per_scene_not_per_scene_object(monkeypatch):
    """Keyed by ``id(scene)``, every run_interference's new scene object loaded them again: a pace sweep kept one
    robot model per point. Now by the scene's reference and content, the least recently used going past a few."""
    loaded = []
    monkeypatch.setattr(harness, "load_models", lambda scene: loaded.append(scene.name) or (object(), None, None))
    monkeypatch.setattr(harness, "_EXECUTOR_MODELS", type(harness._EXECUTOR_MODELS)())
    first = harness._executor_models(load_scene("pr2_two_cups_side"))[0]
    assert harness._executor_models(load_scene("pr2_two_cups_side"))[0] is first
    assert loaded == ["pr2_two_cups_side"]
    moved = load_scene("pr2_two_cups_side")  # the same name, another content: its own models
    moved = dataclasses.replace(moved, robot=dataclasses.replace(moved.robot, torso_lift=moved.robot.torso_lift / 2))
    assert harness._executor_models(moved)[0] is not first and len(loaded) == 2
    for i in range(2 * harness.EXECUTOR_MODELS_KEPT):
        harness._executor_models(dataclasses.replace(moved, name=f"s{i}", source=f"s{i}.toml"))
    assert len(harness._EXECUTOR_MODELS) == harness.EXECUTOR_MODELS_KEPT
