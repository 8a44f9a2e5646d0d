"""``foresight bench tracker`` runs the core over a library's reaches and prints its table."""

from __future__ import annotations

import re

import pytest

from services.tracker import bench
from services.tracker.bench import main


def test_bench_tracker_prints_a_row_per_demonstration_and_the_time(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--demos", "2", "--noise-m", "0.01"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].split()[:3] == ["demo", "reaches", "lag"]
    rows = out[2:4]
    assert len(rows) == 2 and all(int(r.split()[2]) >= 1 for r in rows)  # a reach found in each
    assert out[4].startswith("time per frame fitted: median") and "33.3 ms" in out[4]
    # the baseline in the same run: the same frames, each fit from the first guess; the ratio of the medians
    base, ratio = re.fullmatch(r"baseline, each fit from the first guess \(no warm start\): median ([\d.]+) ms, "
                               r"p99 [\d.]+ ms; the warm start ([\d.]+)x as fast", out[5]).groups()
    core_ms = float(re.search(r"median ([\d.]+) ms", out[4]).group(1))
    assert float(base) > 0 and abs(float(ratio) - float(base) / core_ms) <= 0.05 + 0.02 * float(ratio)


def test_bench_tracker_at_120_hz_gives_the_poses_of_30_hz(capsys: pytest.CaptureFixture[str]) -> None:
    """The bench played the library's 30 Hz samples at the sensor's rate (the person 4x faster at 120 Hz); now it
    samples the recorded motion at that rate, and the tracker's poses come at the library's 30 a second."""
    rows = {}
    for rate in ("30", "120"):
        assert main(["--demos", "1", "--rate-hz", rate, "--no-baseline"]) == 0  # the baseline's own test: above
        out = capsys.readouterr().out.splitlines()
        assert not any(line.startswith("baseline") for line in out)
        assert out[1].split()[:5] == ["demo", "reaches", "lag", "poses", "samples"]
        rows[rate] = out[2].split()
    assert rows["30"][2] == rows["120"][2] == "1"  # one reach each
    assert abs(int(rows["120"][4]) - int(rows["30"][4])) <= 3  # as many poses (was 4x as many)
    assert abs(int(rows["120"][3]) - int(rows["30"][3])) <= 3  # the same lag, in the library's samples


def test_the_baseline_core_fits_every_frame_without_a_prior(monkeypatch) -> None:
    priors = []
    real = bench.KeypointFit.fit

    def seen(self, points, observed=None, prior=None):
        priors.append(prior is not None)
        return real(self, points, observed, prior)

    monkeypatch.setattr(bench.KeypointFit, "fit", seen)
    cold = bench.TrackerCore()
    cold.fit = bench._ColdFit(model=cold.model)
    stand = cold.model.joint_positions(bench.source_library(None).demos[0].features[:3])
    for i, p in enumerate(stand):
        cold.on_frame(i / 30, list(bench.POINT_NAMES), p)
    assert cold.accepted == 3 and priors and not any(priors)


@pytest.mark.parametrize(("args", "message"), [
    (["--rate-hz", "0"], "--rate-hz must be a finite number > 0, got 0"),
    (["--rate-hz", "-5"], "--rate-hz must be a finite number > 0, got -5"),
    (["--rest-s", "-1"], "--rest-s must be a finite number >= 0, got -1"),
    (["--demos", "0"], "--demos must be at least 1, got 0"),
    (["--library", "/nonexistent/library"], "/nonexistent/library"),
])
def test_bad_options_are_one_line(args, message, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("foresight bench tracker: ") and message in err
