"""Table I's results: the comparison with the authors' runs, the spreads over seeds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from services.experiments.authors import TABLE1_RUNS
from services.experiments.heldout import CupClass
from services.experiments.interference import InterferenceConfig, InterferenceResult
from services.experiments.planners import Timing
from services.experiments.protocol import AUTHORS_TRIALS, PAPER
from services.experiments.scoring import RunScore
from shared.runtime import UserError

TRIAL = AUTHORS_TRIALS["pr2_two_cups_side_parallel"]  # what authors_trial returns on the paper's library


def test_the_authors_comparison_puts_sample_standard_deviations_side_by_side() -> None:
    """Theirs were sample (ddof 1), ours population (ddof 0): 7.574 against 7.185 on the same 10 numbers."""
    cfg = InterferenceConfig(scene="pr2_two_cups_side_parallel", protocol="paper", demos=1, seeds=3)
    res = InterferenceResult(cfg, "paper", CupClass("blue_cup", 0, "compound_1", 0.4), [0], trial=TRIAL)
    for seed, value in enumerate((1.0, 2.0, 4.0)):
        for name in ("basic", "least_penetration", "current"):
            res.runs.append(RunScore(0, seed, name, value, 0.0, 0.0, 0.1, 0.0, 0.0, None, (), 30.0))
    rows = res.authors_comparison()
    assert [r["planner"] for r in rows] == ["basic", "least_penetration"]
    assert rows[0]["ours"]["std"] == pytest.approx(np.std([1.0, 2.0, 4.0], ddof=1))
    assert rows[0]["authors"]["std"] == pytest.approx(np.std(TABLE1_RUNS["basic"][0], ddof=1))
    # Table I's (std) is the same sample deviation (it was the population one, 5 % smaller with 10 seeds)
    assert res.per_demo("basic") == ([pytest.approx(7 / 3)], [pytest.approx(np.std([1.0, 2.0, 4.0], ddof=1))])


@pytest.mark.parametrize(("protocol", "volume", "iterations"), [("paper", "paper", 51), ("product", None, 50)])
def test_the_json_says_the_volume_and_iterations_that_ran(protocol, volume, iterations) -> None:
    """The paper protocol's JSON said "volume": null and "iterations": null where `paper` and 51 ran."""
    from services.predictor.volumes import DEFAULT_VOLUME

    res = InterferenceResult(InterferenceConfig(protocol=protocol, seeds=1), "synthetic",
                             CupClass("blue_cup", 0, "blue_cup", 0.0), [0])
    for name in ("basic", "least_penetration", "current"):
        res.runs.append(RunScore(0, 0, name, 1.0, 0.0, 0.0, 0.1, 0.0, 0.0, 5, ("red_cup",), 30.0))
    data = res.to_json()
    assert data["volume"] == (volume or DEFAULT_VOLUME) and data["timing"]["iterations"] == iterations


def test_one_seed_has_no_standard_deviation_to_print() -> None:
    """With one seed the table printed "(0.000)", a spread of runs that were not run."""
    def table(seeds: int) -> list[str]:
        res = InterferenceResult(InterferenceConfig(seeds=seeds), "synthetic", CupClass("blue_cup", 0, "blue_cup",
                                                                                         0.0), [0])
        for seed in range(seeds):
            for name in ("basic", "least_penetration", "current"):
                res.runs.append(RunScore(0, seed, name, 1.0 + seed, 0.0, 0.0, 0.1, 0.0, 0.0, 5, ("red_cup",), 30.0))
        return [ln for ln in res.lines() if ln.strip().startswith("#0")]

    assert "(  n/a)" in table(1)[0] and "(0.000)" not in table(1)[0]
    assert "(0.707)" in table(2)[0]


def test_the_table_says_why_current_occupancy_equals_basic_stomp() -> None:
    """``eval all --quick`` printed current occupancy = basic STOMP (15.656 both) without a word of why."""
    def said(costs: list[float]) -> list[str]:
        res = InterferenceResult(InterferenceConfig(seeds=2), "synthetic", CupClass("blue_cup", 0, "blue_cup", 0.0),
                                 [0], current_as_basic=costs)
        for seed in range(2):
            for name in ("basic", "least_penetration", "current"):
                res.runs.append(RunScore(0, seed, name, 1.0, 0.0, 0.0, 0.1, 0.0, 0.0, 5, ("red_cup",), 30.0))
        assert res.to_json()["current_runs_as_basic"] == len(costs)
        return [ln for ln in res.lines() if ln.startswith("current occupancy executed basic STOMP's path")]

    assert said([0.0, 0.0]) == ["current occupancy executed basic STOMP's path, state for state, in 2 of 2 runs "
                                "(its chosen paths' human cost: 0 at every step: the human's present posture never "
                                "lay on the path it chose)"]
    assert said([0.0]) == ["current occupancy executed basic STOMP's path, state for state, in 1 of 2 runs "
                           "(its chosen paths' human cost: 0 at every step: the human's present posture never "
                           "lay on the path it chose)"]
    assert said([0.0, 0.25])[0].endswith("(its chosen paths' human cost: at most 0.2500)")
    assert said([]) == []


def test_more_demos_than_the_authors_five_run_their_five_then_the_class_s_others() -> None:
    """``--demos 7`` on the authors' trials ran their five and said nothing (docs: the class's others follow)."""
    from services.experiments.heldout import table1_demos

    trial = ("compound_1", (0, 1, 2, 3, 4))
    assert table1_demos(25, 7, trial, 0) == ([0, 1, 2, 3, 4, 5, 6], "the authors' motions, then the class's others")
    assert table1_demos(25, 3, trial, 0) == ([0, 1, 2], "the authors' motions")
    assert table1_demos(4, 3, ("compound_3", (2,)), 0)[0] == [2, 0, 1]  # as the switch orders them
    with pytest.raises(UserError, match="--demos 25: class compound_1 has 25 demonstrations"):
        CupClass("blue_cup", 1, "compound_1", 0.4).held_out(25, 25)
    # beside the authors' runs: their five motions, not the others (which have no run of theirs)
    cfg = InterferenceConfig(scene="pr2_two_cups_side_parallel", protocol="paper", demos=6, seeds=2)
    res = InterferenceResult(cfg, "paper", CupClass("blue_cup", 1, "compound_1", 0.4), list(range(6)), trial=TRIAL)
    for demo in range(6):
        for seed in range(2):
            for name in ("basic", "least_penetration", "current"):
                value = 2.0 if name == "basic" else 1.0 + 9 * (demo == 5)  # #5 would change the ratio
                res.runs.append(RunScore(demo, seed, name, value, 0.0, 0.0, 0.1, 0.0, 0.0, 5, ("red_cup",), 30.0))
    assert [r["motion"] for r in res.authors_comparison()] == [25, 26, 27, 28, 29] * 2
    assert res.authors_lines()[-1].endswith("the paper protocol here 2.0x")


@pytest.mark.parametrize(("protocol", "pace", "timing"), [
    ("paper", None, {"path_per_step": 0.05}), ("paper", 0.1, {"path_per_step": 0.1}),
    ("product", None, {"robot_speed": 0.25})])
def test_the_json_says_the_stomp_and_the_pace_that_ran(protocol, pace, timing) -> None:
    """``--protocol paper --json`` said "rollouts": null, "reuse": null where 10 and 5 ran, and "robot_speed": 0.25,
    which paces nothing there, not the path length per step it ran."""
    cfg = InterferenceConfig(scene=PAPER.table1_scene if protocol == "paper" else "pr2_two_cups_side",
                             protocol=protocol, seeds=1, path_per_step=pace)
    res = InterferenceResult(cfg, "synthetic", CupClass("blue_cup", 0, "blue_cup", 0.0), [0])
    for name in ("basic", "least_penetration", "current"):
        res.runs.append(RunScore(0, 0, name, 1.0, 0.0, 0.0, 0.1, 0.0, 0.0, 5, ("red_cup",), 30.0))
    ran = res.to_json()["timing"]
    assert ran["rollouts"] == 10 and ran["reuse"] == 5
    assert {k: v for k, v in ran.items() if k in ("robot_speed", "path_per_step")} == pytest.approx(timing)
    asked = dataclasses.replace(cfg, timing=Timing(rollouts=6, reuse=2))
    ran = InterferenceResult(asked, "synthetic", res.human, [0], res.runs).to_json()["timing"]
    assert (ran["rollouts"], ran["reuse"]) == (6, 2)


def test_a_result_not_run_on_the_authors_trial_is_not_compared_with_their_runs() -> None:
    """A generated library's compound_1 (any CSV library has one) was compared with the authors' costs by its name."""
    cfg = InterferenceConfig(scene="pr2_two_cups_side_parallel", protocol="paper", demos=1, seeds=1)
    res = InterferenceResult(cfg, "generated", CupClass("blue_cup", 0, "compound_1", 0.4), [0])  # no trial
    for name in ("basic", "least_penetration"):
        res.runs.append(RunScore(0, 0, name, 1.0, 0.0, 0.0, 0.1, 0.0, 0.0, None, (), 30.0))
    assert not res.authors_trials() and res.authors_comparison() == []
    assert dataclasses.replace(res, trial=TRIAL).authors_comparison() != []
