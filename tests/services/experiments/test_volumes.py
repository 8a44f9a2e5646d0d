"""``foresight eval volumes``: the rule that picks a default volume, and the command's bad input."""

from __future__ import annotations

import math

import pytest

from services.experiments.cli import main as eval_main
from services.experiments.volumes import VolumesConfig, VolumeScore, VolumesResult, run_volumes


def _score(volume: str, contact: float, clearance: float, reached: int = 10, away: float = 2.0) -> VolumeScore:
    return VolumeScore(volume=volume, runs=10, contact_s=contact, runs_in_contact=int(contact > 0),
                       median_min_clearance=clearance, time_near_s=0.0, reached=reached, settle_step=1.0,
                       away_step=away, ends_at_human_cup=0, planning_ms=100.0)


def test_the_rule_picks_the_fewest_contacts_then_the_largest_clearance():
    res = VolumesResult(VolumesConfig(), scores=[_score("paper", 0.5, 0.10), _score("spread", 0.0, 0.12),
                                                 _score("demos", 0.0, 0.15)])
    assert res.choice()[0] == "demos"
    assert "demos: 0.00 s in contact" in res.choice()[1]
    assert "rule's choice: demos" in res.lines()[-1]


def test_the_rule_excludes_a_volume_that_misses_a_goal_or_leaves_the_human_later():
    res = VolumesResult(VolumesConfig(), scores=[_score("paper", 0.5, 0.10, away=2.0),
                                                 _score("spread", 0.0, 0.20, reached=9),
                                                 _score("demos", 0.0, 0.20, away=3.0),
                                                 _score("timed", 0.2, 0.11, away=1.0)])
    best, why = res.choice()
    assert best == "timed"
    assert "demos, spread" in why
    nothing = VolumesResult(VolumesConfig(), scores=[_score("paper", 0.0, 0.1, reached=3)])
    assert nothing.choice()[0] is None


def test_the_rule_without_paper_compares_only_contacts():
    res = VolumesResult(VolumesConfig(), scores=[_score("spread", 0.3, 0.2, away=math.nan),
                                                 _score("timed", 0.1, 0.1, away=math.nan)])
    assert res.choice()[0] == "timed"


def test_unknown_volumes_are_refused(capsys):
    with pytest.raises(ValueError, match="volumes must be some of"):
        run_volumes(VolumesConfig(volumes=("paper", "blob")))
    with pytest.raises(SystemExit) as exit_:
        eval_main(["volumes", "--volumes", "paper,blob"])
    assert exit_.value.code == 2
    assert "--volumes: blob" in capsys.readouterr().err


@pytest.mark.parametrize(("switch_demos", "runs", "said"), [
    (2, 2, "the switch (2 demonstrations, each held out in turn)"),
    (0, 25, "the switch (25 demonstrations of the class, each held out in turn)"),
    (0, None, "the switch (every demonstration of the class, each held out in turn)")])
def test_the_table_says_which_switch_ran(switch_demos, runs, said):
    """It said "every demonstration held out in turn" under --switch-demos 2."""
    raw = {} if runs is None else {v: {"interference_runs": [], "switch_runs": [{}] * runs} for v in ("paper", "demos")}
    res = VolumesResult(VolumesConfig(switch_demos=switch_demos), "synthetic", [_score("paper", 0.0, 0.1)], raw)
    assert said in res.lines()[0], res.lines()[0]
