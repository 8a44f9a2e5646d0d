"""``foresight bench tracker-live``: the tracker as a process behind a router, its poses' delay per sensor rate."""

from __future__ import annotations

import math
import tempfile

import pytest

from services.tracker.live_bench import _frames, main
from shared.human import HumanModel
from shared.synthetic import generate_library


def test_the_bench_prints_a_row_per_rate_with_the_poses_it_got_back(tmp_path, capsys) -> None:
    assert main(["--rates", "30,90", "--rest-s", "0.5", "--out", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert f"logs in {tmp_path}" in lines[0]
    assert lines[1].split() == ["rate", "Hz", "frames", "poses", "median", "ms", "max", "ms", "vs", "30", "Hz"]
    rows = [line.split() for line in lines[2:]]
    assert [r[0] for r in rows] == ["30", "90"]
    feats = generate_library(seed=0).demos[0].features
    for rate, frames, poses, median, worst, ratio in rows:
        # the frames sent are the demonstration's at that rate; how many poses come back in real time depends on
        # the machine's load: at least one, with a delay
        assert int(frames) == len(_frames(feats, float(rate), 0.5, HumanModel()))
        assert int(poses) >= 1 and 0 <= float(median) <= float(worst) and math.isfinite(float(worst))
        assert ratio.endswith("x") and float(ratio[:-1]) > 0
    assert rows[0][5] == "1.0x" and (tmp_path / "tracker.log").is_file()


def test_without_out_its_temporary_logs_are_removed(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert main(["--rates", "30", "--rest-s", "0.5"]) == 0
    assert "logs removed at the end (--out keeps them)" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []  # mkdtemp's folder was left behind


def test_bad_rates_are_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--rates", "30,fast"])
    assert exc.value.code == 2
    assert "--rates: '30,fast' is not a comma-separated list of numbers" in capsys.readouterr().err


@pytest.mark.parametrize(("args", "message"), [
    (["--rest-s", "-1"], "--rest-s must be a finite number >= 0, got -1"),
    (["--library", "/nonexistent/library"], "/nonexistent/library"),
])
def test_bad_options_are_one_line(args, message, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("foresight bench tracker-live: ") and message in err
