"""The report's verdicts: reproduced or not, by how much, and the measured cause."""

from __future__ import annotations

import math

from services.experiments.heldout import CupClass
from services.experiments.interference import InterferenceConfig, InterferenceResult, RunScore, ratio_text
from services.experiments.verdicts import table1_verdict


def table1(basic: float, lp: float, early: float = 0.0) -> InterferenceResult:
    res = InterferenceResult(InterferenceConfig(seeds=1), "synthetic", CupClass("blue_cup", 0, "blue_cup", 0.0), [0])
    for name, value in (("basic", basic), ("least_penetration", lp), ("current", basic)):
        res.runs.append(RunScore(0, 0, name, value, 0.0, early if name == "least_penetration" else 0.0, 0.12,
                                 0.0, 0.0, 5, ("red_cup",), 30.0))
    return res


def test_table1_verdicts_name_the_ratio_and_the_cause():
    assert table1_verdict(table1(25.0, 0.5)).startswith("**reproduced**: 50.0x")
    v = table1_verdict(table1(20.0, 10.0, early=9.0))
    assert v.startswith("**not reproduced**: 2.0x") and "90% of least penetration's interference" in v
    none = table1_verdict(table1(0.0, 0.0))
    assert none.startswith("**not reproduced (no ratio)**") and "+0.120 m" in none


def test_ratio_text():
    assert ratio_text(2.345) == "2.3x" and ratio_text(math.inf) == "inf"
    assert ratio_text(math.nan) == ratio_text(None) == "n/a (0 / 0)"
