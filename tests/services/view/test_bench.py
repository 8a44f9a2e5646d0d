"""``foresight bench live``: its variants and the summary with the view's peak memory (the demo runs faked)."""

from __future__ import annotations

import math

import services.view.bench as bench


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
    monkeypatch.setattr(bench, "stall_line", lambda: "the machine's stall factor")
    assert bench.main(["--rounds", "2", "--slow-client", "--out", str(tmp_path)]) == 0
    assert sorted(ran) == sorted([*bench.VARIANTS, bench.SLOW] * 2) and ran[:4] != ran[4:]  # each round, rotated
    out = capsys.readouterr().out
    assert "foresight view, its client stalled, a client connected: 50.0 ms" in out
    assert "200 MB with a client reading, 300 MB with one that reads nothing (1.50x)" in out
    assert out.splitlines()[-1] == "the machine's stall factor"  # how much of any p99 is the machine's, last
    bench.main(["--rounds", "1", "--out", str(tmp_path)])
    assert bench.SLOW not in ran[8:] and "peak memory, median" not in capsys.readouterr().out
