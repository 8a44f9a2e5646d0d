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
    assert rows["one frame, first guess (baseline)"][2] == "1.0x"
    for values in rows.values():
        p50_ms, _, _, err_mm, _ = values
        assert float(p50_ms) > 0 and 0 < float(err_mm) < 20  # 1 cm of noise: the fit is within centimetres
