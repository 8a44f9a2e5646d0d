"""``foresight bench live``: its variants, the view's peak memory and the summary (the demo runs faked)."""

from __future__ import annotations

import math
import os

import services.view.bench as bench


def test_peak_memory_of_a_live_process_and_of_none() -> None:
    assert bench.peak_rss_mb(os.getpid()) > 10.0
    assert math.isnan(bench.peak_rss_mb(2**22 + 17))  # no such process


def test_slow_client_runs_a_stalled_client_beside_the_others_and_compares_the_views_memory(monkeypatch, capsys,
                                                                                            tmp_path) -> None:
    ran = []

    def fake_run(out, variant, demo_args):
        ran.append(variant)
        stalled = variant == bench.SLOW
        counts = {"nothing read (a stalled client)": 0} if stalled else {"/viz/plan": 40}
        peak = 300.0 if stalled else (200.0 if variant == "view" else math.nan)
        return {"mcap_path": f"{variant}.mcap"}, counts, peak

    class Stat:
        p50, p99 = 20.0, 50.0

    monkeypatch.setattr(bench, "_run", fake_run)
    monkeypatch.setattr(bench, "log_latencies", lambda path: {"pose_to_plan": Stat()})
    assert bench.main(["--rounds", "2", "--slow-client", "--out", str(tmp_path)]) == 0
    assert sorted(ran) == sorted([*bench.VARIANTS, bench.SLOW] * 2) and ran[:4] != ran[4:]  # each round, rotated
    out = capsys.readouterr().out
    assert "foresight view, its client stalled, a client connected: 50.0 ms" in out
    assert "200 MB with a client reading, 300 MB with one that reads nothing (1.50x)" in out
    bench.main(["--rounds", "1", "--out", str(tmp_path)])
    assert bench.SLOW not in ran[8:] and "peak memory, median" not in capsys.readouterr().out
