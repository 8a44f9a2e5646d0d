"""``foresight bench keypoints`` prints the three ways with times, the ratio to the baseline and the joint error."""

from __future__ import annotations

import pytest

from services.bench import main
from shared.keypoints import bench

AT_ONCE = "every frame at once (a library)"


def test_bench_prints_its_table(capsys) -> None:
    assert main(["keypoints", "--demos", "1", "--noise-m", "0.01"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert "1 demonstrations" in lines[0] and "noise 1 cm per axis" in lines[0]
    rows = {ln[:36].strip(): ln[36:].split() for ln in lines[2:5]}
    assert set(rows) == {"one frame, warm start (live)", "one frame, first guess (baseline)", AT_ONCE}
    base_ms = float(rows["one frame, first guess (baseline)"][0])
    for name, values in rows.items():
        p50_ms, p99_ms, ratio, err_mm, err99_mm = values
        assert float(p50_ms) > 0 and 0 < float(err_mm) < 20  # 1 cm of noise: the fit is within centimetres
        assert float(err99_mm) >= float(err_mm)
        # one call for every frame: only its mean per frame, no p99 (it was the mean again)
        assert p99_ms == "-" if name == AT_ONCE else float(p99_ms) >= float(p50_ms)
        # each row's ratio is the baseline's median over its own (both printed rounded: 0.01 ms, 0.1x)
        assert ratio.endswith("x")
        assert abs(float(ratio[:-1]) - base_ms / float(p50_ms)) <= 0.05 + 0.01 * base_ms / float(p50_ms)
    assert lines[5].startswith("every frame at once is one call") and "the mean" in lines[5]


def test_the_batch_fit_is_warmed_up_before_it_is_timed(monkeypatch, capsys) -> None:
    calls = []
    real = bench.KeypointFit.fit_sequences

    def counted(self, points, *args, **kwargs):
        calls.append(points.shape[1])
        return real(self, points, *args, **kwargs)

    monkeypatch.setattr(bench.KeypointFit, "fit_sequences", counted)
    assert bench.main(["--demos", "1"]) == 0
    assert len(calls) == 2 and calls[0] < calls[1]  # a short warm-up, then every frame


@pytest.mark.parametrize(("args", "message"), [
    (["--demos", "0"], "--demos must be at least 1, got 0"),
    (["--noise-m", "-0.01"], "--noise-m must be a finite number >= 0, got -0.01"),
    (["--library", "/nonexistent/library"], "/nonexistent/library"),
])
def test_bad_options_are_one_line(args, message, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        bench.main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("foresight bench keypoints: ") and message in err
