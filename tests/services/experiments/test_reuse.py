"""Basic STOMP planned once per seed: the checks that allow it, and Table I the same with or without it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from services.experiments import interference
from services.experiments.harness import RunRecord, RunSpec, run_lockstep
from services.experiments.heldout import HeldOutModels, human_file, samples_per_tick
from services.experiments.interference import InterferenceConfig, current_as_basic, run_interference
from services.experiments.planners import VARIANTS, Timing, build_planner
from services.experiments.reuse import first_differing_state, same_human, same_robot, with_human
from shared.library import save_library
from shared.scene import load_scene
from shared.synthetic import generate_library

TIMING = Timing(steps=3, iterations=3)


@pytest.fixture(scope="module")
def two_basic_runs(tmp_path_factory):
    """Basic STOMP, seed 1, on two demonstrations of one class; and a least-penetration run of the second."""
    root = tmp_path_factory.mktemp("reuse")
    scene = load_scene("pr2_two_cups_side")
    lib = generate_library(8, 4, seed=4, scene=scene)
    demos = lib.by_class(0)[:2]
    model = HeldOutModels(lib, scene, root, components=2).without(demos)
    basic = build_planner(scene, ["red_cup"], False, TIMING, compile=False)
    least = build_planner(scene, ["red_cup"], True, TIMING, compile=False)

    def run(demo, planner):
        spec = RunSpec(scene, model, human_file(lib, demo, root), samples_per_tick(demo, TIMING.steps),
                       steps=TIMING.steps, period_s=TIMING.period_s, seed=1)
        return run_lockstep(spec, planner)

    return run(demos[0], basic), run(demos[1], basic), run(demos[1], least)


def test_basic_stomp_executes_the_same_path_whichever_demonstration_streams(two_basic_runs) -> None:
    a, b, _ = two_basic_runs
    assert len(a.poses) and len(b.poses)
    assert not same_human(a, b)  # two demonstrations
    assert same_robot(a, b) and first_differing_state(a, b) is None
    np.testing.assert_array_equal(a.q(), b.q())


def test_the_human_side_of_a_basic_run_is_that_of_a_least_penetration_run_of_the_same_demonstration(
        two_basic_runs) -> None:
    _, b, lp = two_basic_runs
    assert same_human(b, lp)
    assert not same_robot(b, lp)  # least penetration plans around the human


def test_same_robot_ignores_the_planning_time_but_not_a_configuration(two_basic_runs) -> None:
    a, b, _ = two_basic_runs
    timed = dataclasses.replace(b, plans=[dataclasses.replace(p, planning_ms=p.planning_ms + 1) for p in b.plans])
    assert same_robot(a, timed)
    states = list(b.states)
    k = len(states) // 2
    states[k] = dataclasses.replace(states[k], q=states[k].q + np.r_[1e-12, np.zeros(len(states[k].q) - 1)])
    moved = dataclasses.replace(b, states=states)
    assert not same_robot(a, moved) and first_differing_state(a, moved) == states[k].stamp
    assert not same_robot(a, dataclasses.replace(b, states=b.states[:-1]))


def test_current_as_basic_gives_the_human_cost_of_a_run_that_executed_basic_stomps_path(two_basic_runs) -> None:
    """Table I's current occupancy equal to basic STOMP (15.656 both, ``eval all --quick``) was printed unexplained."""
    a, b, lp = two_basic_runs
    assert current_as_basic({"basic": a, "current": b}) == max(float(p.cost_human[p.chosen]) for p in b.plans)
    assert current_as_basic({"basic": a, "current": lp}) is None  # planned around the human: another path
    assert current_as_basic({"basic": a, "least_penetration": lp}) is None  # no current run (``eval volumes``)


def test_same_human_sees_one_pose_changed(two_basic_runs) -> None:
    _, b, lp = two_basic_runs
    poses = list(lp.poses)
    poses[3] = dataclasses.replace(poses[3], features=poses[3].features + 1e-9)
    assert not same_human(b, dataclasses.replace(lp, poses=poses))


def test_with_human_keeps_the_robot_of_one_run_and_the_human_of_the_other(two_basic_runs) -> None:
    a, _, lp = two_basic_runs
    mixed = with_human(a, lp)
    assert mixed.plans is a.plans and mixed.states is a.states and mixed.result is a.result
    assert mixed.poses is lp.poses and mixed.posteriors is lp.posteriors and mixed.occupancy is lp.occupancy


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A small library (8 classes x 4 demonstrations) and the directory its held-out models are trained into once."""
    root = tmp_path_factory.mktemp("table1")
    save_library(generate_library(8, 4, seed=4, scene=load_scene("pr2_two_cups_side")), root / "lib.npz")
    return root / "lib.npz", root / "models"


def _table1(tmp_path, small, **kw) -> tuple[interference.InterferenceResult, list[str]]:
    said: list[str] = []
    library, models_dir = small
    cfg = InterferenceConfig(library=str(library), demos=2, seeds=2, timing=TIMING, components=2,
                             variants=("basic", "least_penetration"), models_dir=models_dir,
                             work_dir=tmp_path / "work", **kw)
    return run_interference(cfg, progress=said.append, compile=False), said


def _scores(res) -> dict:
    return {(r.planner, r.demo, r.seed): dataclasses.replace(r, planning_ms=0.0, borrowed=False) for r in res.runs}


@pytest.mark.filterwarnings("error::RuntimeWarning")  # the table of two planners had NaN columns for the third
def test_table1_scores_basic_stomp_the_same_planned_once_per_seed_or_on_every_demonstration(tmp_path, small) -> None:
    once, said = _table1(tmp_path, small)
    every, _ = _table1(tmp_path, small, basic_once=False)
    assert once.borrowed == 1 and every.borrowed == 0  # seed 1 of the second demonstration
    assert _scores(once) == _scores(every)
    assert once.ratio() == every.ratio()
    assert sum("basic STOMP ignores the human" in s for s in said) == 1
    assert [(r.planner, r.demo, r.seed) for r in once.runs] == [(r.planner, r.demo, r.seed) for r in every.runs]
    assert "basic STOMP ignores the human" in "\n".join(once.lines())
    data = once.to_json()
    assert [(r.demo, r.seed) for r in once.runs if r.borrowed] == [(once.demos[1], 1)]
    assert data["basic_runs_borrowed"] == 1 and "current" not in data and "current" not in data["reached"]


def test_a_basic_planner_whose_path_depends_on_the_human_is_run_on_every_demonstration(tmp_path, small,
                                                                                          monkeypatch) -> None:
    # a "basic" that costs the human: its path differs between demonstrations, so the first seed's check must fail
    costed = dict(VARIANTS, basic=dataclasses.replace(VARIANTS["basic"], human_cost=True))
    monkeypatch.setattr(interference, "VARIANTS", costed)
    res, said = _table1(tmp_path, small)
    assert res.borrowed == 0
    assert any("differs from the first demonstration's" in s and "every run is made" in s for s in said)
    assert len(res.runs) == 2 * 2 * 2


def test_table1_counts_the_runs_where_current_occupancy_executed_basic_stomps_path(tmp_path, small,
                                                                                  monkeypatch) -> None:
    # a "current" that costs nothing plans what basic STOMP plans: every run is counted, and the table says so
    blind = dict(VARIANTS, current=dataclasses.replace(VARIANTS["current"], human_cost=False))
    monkeypatch.setattr(interference, "VARIANTS", blind)
    runs: dict[tuple[str, Path, int], RunRecord] = {}  # (variant, human file, seed) -> its record
    real = interference.run_lockstep

    def recorded(spec: RunSpec, planner) -> RunRecord:
        rec = runs[(spec.method, spec.human, spec.seed)] = real(spec, planner)
        return rec

    monkeypatch.setattr(interference, "run_lockstep", recorded)
    library, models_dir = small
    res = run_interference(InterferenceConfig(library=str(library), demos=2, seeds=1, timing=TIMING, components=2,
                                              variants=("basic", "current"), models_dir=models_dir,
                                              work_dir=tmp_path / "work"), progress=lambda _: None, compile=False)
    humans = sorted({h for _, h, _ in runs})
    costs = [max(float(p.cost_human[p.chosen]) for p in runs[("current", h, 0)].plans) for h in humans]
    assert len(humans) == 2 and res.current_as_basic == costs
    assert res.to_json()["current_runs_as_basic"] == 2
    assert any(ln.startswith("current occupancy executed basic STOMP's path, state for state, in 2 of 2 runs")
               for ln in res.lines())
