"""``foresight bench human``: the rotation of its variants and its summary (the demo runs faked)."""

from __future__ import annotations

import pytest

import services.tracker.demo_bench as bench


class _Stat:
    def __init__(self, p50: float, p99: float) -> None:
        self.p50, self.p99 = p50, p99


def test_each_variant_runs_each_round_and_its_median_p99_is_compared_with_the_replayers(monkeypatch, capsys,
                                                                                     tmp_path) -> None:
    ran = []
    p99 = {"replayer": 50.0, "keypoints": 55.0, "noisy": 70.0}

    def fake_run(out, variant, demo_args):
        ran.append(variant)
        return {"mcap_path": variant}

    def fake_latencies(path):
        stats = {"pose_to_plan": _Stat(20.0, p99[path])}
        if path != "replayer":
            stats |= {"keypoints_to_pose": _Stat(3.0, 6.0), "keypoints_to_plan": _Stat(25.0, p99[path] + 5)}
        return stats

    monkeypatch.setattr(bench, "_run", fake_run)
    monkeypatch.setattr(bench, "log_latencies", fake_latencies)
    monkeypatch.setattr(bench, "stall_line", lambda: "the machine's stall factor")
    assert bench.main(["--rounds", "3", "--out", str(tmp_path)]) == 0
    assert sorted(ran) == sorted(list(bench.VARIANTS) * 3) and len({tuple(ran[i:i + 3]) for i in (0, 3, 6)}) == 3
    out = capsys.readouterr().out
    assert "median pose -> plan p99 with the replayer: 50.0 ms" in out
    assert "the tracker (clean keypoints): 55.0 ms, +5.0 ms (target <= +10 ms: met)" in out
    assert "the tracker (2 cm noise): 70.0 ms, +20.0 ms (target <= +10 ms: missed)" in out
    assert out.splitlines()[-1] == "the machine's stall factor"  # how much of any p99 is the machine's, last


def test_no_rounds_is_one_line_before_any_run(monkeypatch, capsys) -> None:
    def fake_run(out, variant, demo_args):
        raise AssertionError("a demo ran before the options were checked")

    monkeypatch.setattr(bench, "_run", fake_run)
    with pytest.raises(SystemExit) as exc:
        bench.main(["--rounds", "0"])
    assert exc.value.code == 2  # was statistics.StatisticsError (the median of no runs) after the table's header
    assert capsys.readouterr().err.strip() == "foresight bench human: error: --rounds must be at least 1, got 0"
