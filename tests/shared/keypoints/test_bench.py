"""``foresight bench keypoints`` prints the three ways with times, the ratio to the baseline and the joint error."""

from __future__ import annotations

from services.bench import main


def test_bench_prints_its_table(capsys) -> None:
    assert main(["keypoints", "--demos", "1", "--noise-m", "0.01"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert "1 demonstrations" in lines[0] and "noise 1 cm per axis" in lines[0]
    rows = {ln[:36].strip(): ln[36:].split() for ln in lines[2:]}
    assert set(rows) == {"one frame, warm start (live)", "one frame, first guess (baseline)",
                         "every frame at once (a library)"}
    base_ms = float(rows["one frame, first guess (baseline)"][0])
    for values in rows.values():
        p50_ms, p99_ms, ratio, err_mm, err99_mm = values
        assert float(p50_ms) > 0 and 0 < float(err_mm) < 20  # 1 cm of noise: the fit is within centimetres
        assert float(p99_ms) >= float(p50_ms) and float(err99_mm) >= float(err_mm)
        # each row's ratio is the baseline's median over its own (both printed rounded: 0.01 ms, 0.1x)
        assert ratio.endswith("x")
        assert abs(float(ratio[:-1]) - base_ms / float(p50_ms)) <= 0.05 + 0.01 * base_ms / float(p50_ms)
