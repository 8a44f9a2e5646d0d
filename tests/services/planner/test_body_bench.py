"""``foresight bench body`` runs and prints its table (numbers are for people, not asserted)."""

from __future__ import annotations

import pytest

from services.bench import main


def test_the_bench_prints_a_row_per_resting_person_and_term_and_the_ratio(capsys) -> None:
    assert main(["body", "--steps", "2", "--no-compile"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = [ln.split() for ln in out if ln.startswith(("blue_cup", "red_cup"))]
    assert [r[:2] for r in rows] == [["blue_cup", "on"], ["blue_cup", "off"], ["red_cup", "on"], ["red_cup", "off"]]
    assert all(r[2] in ("blue_cup", "red_cup") and float(r[3]) < 1.0 and float(r[4]) > 0 for r in rows), out
    assert out[-1].startswith("step time with the term / without: ") and out[-1].endswith("x")


def test_bad_options_are_one_line_errors(capsys) -> None:
    with pytest.raises(SystemExit) as e:
        main(["body", "--steps", "1"])
    assert e.value.code == 2 and "--steps must be >= 2" in capsys.readouterr().err
