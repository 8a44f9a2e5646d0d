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
    assert out[4].startswith("time per frame fitted: median") and "33.3 ms" in out[4]


def test_bench_tracker_at_120_hz_gives_the_poses_of_30_hz(capsys: pytest.CaptureFixture[str]) -> None:
    """The bench played the library's 30 Hz samples at the sensor's rate (the person 4x faster at 120 Hz); now it
    samples the recorded motion at that rate, and the tracker's poses come at the library's 30 a second."""
    rows = {}
    for rate in ("30", "120"):
        assert main(["--demos", "1", "--rate-hz", rate]) == 0
        out = capsys.readouterr().out.splitlines()
        assert out[1].split()[:5] == ["demo", "reaches", "lag", "poses", "samples"]
        rows[rate] = out[2].split()
    assert rows["30"][2] == rows["120"][2] == "1"  # one reach each
    assert abs(int(rows["120"][4]) - int(rows["30"][4])) <= 3  # as many poses (was 4x as many)
    assert abs(int(rows["120"][3]) - int(rows["30"][3])) <= 3  # the same lag, in the library's samples
