"""``foresight bench tracker`` runs the core over a library's reaches and prints its table."""

from __future__ import annotations

import pytest

from services.tracker.bench import main


def test_bench_tracker_prints_a_row_per_demonstration_and_the_time(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--demos", "2", "--noise-m", "0.01"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].split()[:3] == ["demo", "reaches", "lag"]
    rows = out[2:4]
    assert len(rows) == 2 and all(int(r.split()[2]) >= 1 for r in rows)  # a reach found in each
    assert out[4].startswith("time per frame: median") and "33.3 ms" in out[4]
