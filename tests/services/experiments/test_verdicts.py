"""The report's verdicts: reproduced or not, by how much, and the measured cause."""

from __future__ import annotations

import math

from services.experiments.heldout import CupClass
from services.experiments.interference import InterferenceConfig, InterferenceResult, ratio_text
from services.experiments.scoring import RunScore
from services.experiments.switch import SwitchConfig, SwitchResult, SwitchRun
from services.experiments.verdicts import switch_verdict, table1_verdict


def table1(basic: float, lp: float, early: float = 0.0, clearance: float = 0.12) -> InterferenceResult:
    res = InterferenceResult(InterferenceConfig(seeds=1), "synthetic", CupClass("blue_cup", 0, "blue_cup", 0.0), [0])
    for name, value in (("basic", basic), ("least_penetration", lp), ("current", basic)):
        res.runs.append(RunScore(0, 0, name, value, 0.0, early if name == "least_penetration" else 0.0, clearance,
                                 0.0, 0.0, 5, ("red_cup",), 30.0))
    return res


def switch(away: dict[str, list[int | None]]) -> SwitchResult:
    res = SwitchResult(SwitchConfig(), "synthetic", CupClass("red_cup", 0, "red_cup", 0.0))
    for method, steps in away.items():
        for demo, step in enumerate(steps):
            res.runs.append(SwitchRun(demo, method, (), (), (), (), None, step, "red_cup" if step is None else "blue",
                                      None, 0.1, 0.0, 30.0))
    return res


def test_table1_verdicts_name_the_ratio_and_the_cause():
    assert table1_verdict(table1(25.0, 0.5)).startswith("**reproduced**: 50.0x")
    v = table1_verdict(table1(20.0, 10.0, early=9.0))
    assert v.startswith("**not reproduced**: 2.0x") and "90% of least penetration's interference" in v
    none = table1_verdict(table1(0.0, 0.0))
    assert none.startswith("**not reproduced (no ratio: 0 / 0)**") and "do not cross" in none and "+0.120 m" in none


def test_a_table1_verdict_claims_no_crossing_only_where_there_is_none():
    """Basic at 0 read as 'nothing for the prediction to remove' whatever least penetration and the clearance said."""
    worse = table1_verdict(table1(0.0, 1.0, clearance=-0.02))
    assert worse.startswith("**not reproduced**: 0.0x") and "least penetration does (1.000)" in worse
    assert "nothing for the prediction to remove" not in worse and "do not cross" not in worse
    touching = table1_verdict(table1(0.0, 0.0, clearance=-0.02))
    assert "do not cross" not in touching and "within reach of the real human" in touching and "-0.020 m" in touching


def test_switch_verdicts_say_median_and_count_the_runs():
    """Medians were worded as 'never' and 'ever': single runs contradicted them."""
    v = switch_verdict(switch({"prediction": [0, 0, 6], "current": [0, 0, 9]}))
    assert "in the median run neither planner goes for the human's cup" in v and "4 of 6 runs never do" in v
    v = switch_verdict(switch({"prediction": [None, None, 3], "current": [None, None, 2]}))
    assert "in the median run neither planner leaves the human's cup (4 of 6 runs end going for it)" in v
    assert switch_verdict(switch({"prediction": [1, 2, 3], "current": [9, 9, 9]})).startswith("**reproduced**")
    # a median no run had: "leaves at step 2.5" of a run that never went there and one that left at 5 (eval all --quick)
    v = switch_verdict(switch({"prediction": [0, 5], "current": [0, 0]}))
    assert "prediction leaves at step 2.5 (runs: never goes there, 5), current never goes there" in v, v


def test_ratio_text():
    assert ratio_text(2.345) == "2.3x" and ratio_text(math.inf) == "inf"
    assert ratio_text(math.nan) == ratio_text(None) == "n/a (0 / 0)"


def test_no_verdict_rests_on_a_ratio_or_a_switch_that_is_not_there():
    """Least penetration at 0 and basic at 0.0001 read 'reproduced: infx'; a prediction planner that never went for
    the human's cup 'left it 6 steps earlier'; 'leaves at step 0' stood for 'never goes there'; earlier_by in the
    JSON said -14 where the verdict said +0 (it took the settle steps)."""
    v = table1_verdict(table1(0.0001, 0.0))
    assert v.startswith("**not judged (no finite ratio)**") and "least penetration scores 0" in v and "inf" not in v
    never = switch({"prediction": [0, 0, 0], "current": [6, 6, 6]})
    assert switch_verdict(never).startswith("**not judged (no switch to time)**")
    assert "leaves the human's cup 6 steps earlier" not in switch_verdict(never)
    once = switch({"prediction": [4, 4, 4], "current": [0, 0, 0]})
    assert "prediction leaves at step 4, current never goes there" in switch_verdict(once)
    # a median at the run's length (20 steps: None, never left) is no step: "prediction leaves at step 20" was said
    stays = switch({"prediction": [None, None, 3], "current": [0, 0, 0]})
    assert "prediction never leaves it (ends going for it), current never goes there" in switch_verdict(stays)
    assert "leaves at step 20" not in switch_verdict(stays)
    assert switch({"prediction": [1, 2, 3], "current": [9, 9, 9]}).to_json()["earlier_by"] == 7


def test_a_current_planner_that_never_left_is_no_step_difference():
    """It said "reproduced: the prediction planner leaves the human's cup 16 steps earlier" where the current one never
    left (counted as the run's length, 20): a switch that did not happen."""
    v = switch_verdict(switch({"prediction": [4, 4, 4], "current": [None, None, 13]}))
    assert v.startswith("**reproduced**") and "cup 16 steps earlier" not in v, v
    assert ("the prediction planner leaves the human's cup at step 4, the current-occupancy planner never leaves it "
            "within the run's 20 steps: at least 16 steps earlier") in v
    assert "leaves the human's cup 9 steps earlier" in switch_verdict(switch({"prediction": [4], "current": [13]}))
    never = switch_verdict(switch({"prediction": [0, 0, 0], "current": [None, None, None]}))
    assert "the current one never leaves it within the run's 20 steps" in never and "at step 20" not in never
    stays = switch_verdict(switch({"prediction": [None, None, 3], "current": [2, 2, 2]}))
    assert "steps; paper" not in stays and "(paper: 4 against 13)" in stays  # no '-18 steps' to a run that stayed


def test_the_summary_marks_a_median_at_the_runs_length_never():
    from services.experiments.verdicts import summary

    t1 = table1(25.0, 0.5).to_json()
    sw = switch({"prediction": [4, 4, 4], "current": [None, None, 13]}).to_json()
    data = {"protocols": {"product": {"interference": t1, "switch": sw, "switch_mirrored": None,
                                      "verdicts": {"table1": "t", "switch": "s"}}}}
    rows = [ln for ln in summary(["synthetic"], [([], data)], ("product",)) if ln.startswith("| synthetic")]
    assert rows == ["| synthetic | product | 25.000 / 0.500 | 50.0x | 4 / 20 (never) |  |"]
