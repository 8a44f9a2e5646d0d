"""``foresight bench tracker-live``: the tracker as a process behind a router, its poses' delay per sensor rate."""

from __future__ import annotations

import pytest

from services.tracker.live_bench import main


def test_the_bench_prints_a_row_per_rate_with_the_poses_it_got_back(tmp_path, capsys) -> None:
    assert main(["--rates", "30,90", "--rest-s", "0.5", "--out", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[1].split() == ["rate", "Hz", "frames", "poses", "median", "ms", "max", "ms", "vs", "30", "Hz"]
    rows = [line.split() for line in lines[2:]]
    assert [r[0] for r in rows] == ["30", "90"] and all(int(r[2]) > 20 for r in rows)  # a reach's poses came back
    assert rows[0][5] == "1.0x" and (tmp_path / "tracker.log").is_file()


def test_bad_rates_are_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--rates", "30,fast"])
    assert exc.value.code == 2
    assert "--rates: '30,fast' is not a comma-separated list of numbers" in capsys.readouterr().err
