"""One lock-step run of the four services in-process, and the experiment commands on a small budget."""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.experiments.cli import main
from services.experiments.harness import RunSpec, run_lockstep
from services.experiments.heldout import HeldOutModels, human_file, samples_per_tick
from services.experiments.planners import Timing, build_planner
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


def test_interference_command_prints_the_table_i_json(tmp_path, capsys):
    args = ["interference", "--demos", "1", "--seeds", "1", "--steps", "3", "--iterations", "3", "--components", "2",
            "--no-compile", "--models-dir", str(tmp_path / "m"), "--work-dir", str(tmp_path / "w"), "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    for key in ("basic", "least_penetration", "current"):
        assert len(data[key]) == 1 and data[key][0] >= 0
    assert data["scene"] == "pr2_two_cups_side" and data["human_class"] == "blue_cup"
    assert set(data["min_clearance"]) == {"basic", "least_penetration", "current"}


def test_switch_command_prints_the_settle_steps_and_draws_fig9(tmp_path, capsys):
    png = tmp_path / "fig9.png"
    args = ["switch", "--demos", "1", "--steps", "3", "--iterations", "3", "--components", "2", "--no-compile",
            "--models-dir", str(tmp_path / "m"), "--work-dir", str(tmp_path / "w"), "--plot", str(png), "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["switch_steps_prediction"]) == len(data["switch_steps_current"]) == 1
    assert isinstance(data["switch_step_prediction"], float)
    assert png.is_file() and png.stat().st_size > 10_000


@pytest.mark.parametrize(("args", "named"), [(["interference", "--steps", "0"], "--steps"),
                                             (["switch", "--scene", "nowhere"], "nowhere"),
                                             (["interference", "--library", "/no/such/library"], "/no/such/library"),
                                             (["switch", "--human-cup", "green_cup"], "green_cup")])
def test_bad_options_give_one_line(args, named, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(args)
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0]
