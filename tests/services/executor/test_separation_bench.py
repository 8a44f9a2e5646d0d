"""``foresight bench separation`` runs and prints its table (numbers are for people, not asserted)."""

from __future__ import annotations

import re

import pytest

from services.bench import main
from services.executor import separation_bench


def test_the_bench_prints_a_row_per_noise_and_the_time_per_state(capsys) -> None:
    assert main(["separation", "--seeds", "1", "--seconds", "0.4"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = [ln for ln in out if ln.startswith(("none", "1 cm", "2 cm", "0.05 rad"))]
    assert len(rows) == 4 and all(len(r.split()) >= 3 for r in rows), out
    window = re.match(r"time per state .*: median ([\d.]+) ms", out[-2])
    newest, ratio = re.fullmatch(r"baseline, the newest body alone \(window 0\): median ([\d.]+) ms a state; the "
                                 r"window costs ([\d.]+)x as much", out[-1]).groups()
    assert window and float(newest) > 0  # the baseline's figure and the ratio of the two medians, in one run
    assert abs(float(ratio) - float(window.group(1)) / float(newest)) <= 0.05 + 0.02 * float(ratio)


def test_every_guard_of_the_bench_timing_included_has_the_stop_m_asked(monkeypatch, capsys) -> None:
    configs = []
    real = separation_bench.SeparationGuard

    def guard(config, robot, scene):
        configs.append(config)
        return real(config, robot, scene)

    monkeypatch.setattr(separation_bench, "SeparationGuard", guard)
    assert main(["separation", "--seeds", "1", "--seconds", "0.04", "--stop-m", "0.08"]) == 0
    assert "stop_m 0.08 m" in capsys.readouterr().out
    assert len(configs) == 4 * 2 + 2 and {c.stop_m for c in configs} == {0.08}  # the timing's was the default's
    assert sorted(c.window_s for c in configs[-2:]) == [0.0, 0.5]  # the window timed, and the baseline


@pytest.mark.parametrize(("args", "message"), [
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--stop-m", "-1"], "--stop-m must be a finite number >= 0 (0: the guard off), got -1"),
    (["--stop-m", "nan"], "--stop-m must be a finite number >= 0 (0: the guard off), got nan"),
])
def test_bad_options_are_one_line_errors(args, message, capsys) -> None:
    with pytest.raises(SystemExit) as e:
        main(["separation", *args])
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1 and message in err
