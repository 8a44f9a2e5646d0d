"""``foresight bench separation`` runs and prints its table (numbers are for people, not asserted)."""

from __future__ import annotations

from services.bench import main


def test_the_bench_prints_a_row_per_noise_and_the_time_per_state(capsys) -> None:
    assert main(["separation", "--seeds", "1", "--seconds", "0.4"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = [ln for ln in out if ln.startswith(("none", "1 cm", "2 cm", "0.05 rad"))]
    assert len(rows) == 4 and all(len(r.split()) >= 3 for r in rows), out
    assert any(ln.startswith("time per state") for ln in out)


def test_bad_options_are_one_line_errors(capsys) -> None:
    import pytest

    with pytest.raises(SystemExit) as e:
        main(["separation", "--seeds", "0"])
    assert e.value.code == 2 and "--seeds must be >= 1" in capsys.readouterr().err
