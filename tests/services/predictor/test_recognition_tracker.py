"""`foresight eval recognition --through-tracker`: the tracker's poses classified, missed reaches counted."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from services.predictor.gmm import GMMConfig
from services.predictor.recognition import leave_one_out
from services.predictor.recognition import main as eval_main
from services.predictor.recognition_tracker import leave_one_out_tracked
from shared.library import MotionLibrary, save_library
from shared.synthetic import generate_library

GMM = GMMConfig(n_components=3, max_iter=30)


def test_the_recorded_features_as_poses_score_as_leave_one_out(small_library: MotionLibrary) -> None:
    """Poses that are the recording itself, from its first sample: the same log-likelihoods as the recorded protocol's;
    a demonstration without a reach is counted as not recognised at every fraction."""
    sensed: list = [(d.features, 0) for d in small_library.demos]
    plain = leave_one_out(small_library, GMM, n_jobs=1, progress=False)
    same = leave_one_out_tracked(small_library, GMM, sensed, n_jobs=1, progress=False)
    assert np.allclose(same.result.log_likelihood, plain.log_likelihood) and same.result.rates == plain.rates
    assert plain.correct[:, -1].all()  # else the next check could not fail
    sensed[5] = None
    missed = leave_one_out_tracked(small_library, GMM, sensed, n_jobs=1, progress=False)
    assert missed.no_reach.tolist() == [5] and not missed.result.correct[5].any()
    assert missed.result.rates[-1] == pytest.approx(1 - 1 / len(sensed))
    assert "through the tracker, keypoint noise 0 cm, time from recording" in missed.result.name


def test_time_from_tracker_fits_the_cut_demonstrations(small_library: MotionLibrary) -> None:
    sensed: list = [(d.features, 0) for d in small_library.demos]
    cut = leave_one_out_tracked(small_library, GMM, sensed, time_from="tracker", n_jobs=1, progress=False)
    rec = leave_one_out_tracked(small_library, GMM, sensed, n_jobs=1, progress=False)
    assert "time from tracker" in cut.result.name
    assert not np.allclose(cut.result.log_likelihood, rec.result.log_likelihood)


@pytest.fixture(scope="module")
def still_library_path(tmp_path_factory):
    """2 classes x 4 demonstrations; the first one's hand never leaves rest (the tracker starts no reach)."""
    lib = generate_library(n_classes=2, n_demos=4, seed=3)
    first = lib.demos[0]
    still = dataclasses.replace(first, features=np.repeat(first.features[:1], first.n_samples, axis=0))
    path = tmp_path_factory.mktemp("lib") / "still.npz"
    save_library(dataclasses.replace(lib, demos=[still, *lib.demos[1:]]), path)
    return path


def test_the_cli_json_names_the_variant_and_counts_the_missed_reaches(still_library_path, tmp_path, capsys) -> None:
    argv = ["recognition", "--library", str(still_library_path), "--components", "2", "--n-jobs", "1", "--json",
            "--quiet", "--plot", str(tmp_path / "r.png"), "--calibration-plot", str(tmp_path / "c.png"),
            "--through-tracker", "--keypoint-noise-m", "0.01", "--time-from", "tracker"]
    assert eval_main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    label = "through the tracker, keypoint noise 1 cm, time from tracker"
    assert label in data["variant"]
    tracked = data["through_tracker"]
    assert tracked["label"] == label and tracked["n_demos"] == 8 and tracked["keypoint_noise_m"] == 0.01
    assert tracked["no_reach"] == 1 and tracked["no_reach_demos"] == [0] and tracked["starts"][0] is None
    assert tracked["poses"][0] == 0 and min(tracked["poses"][1:]) > 20
    assert len(data["recognition_rates"]) == 10 and max(data["recognition_rates"]) <= 7 / 8


@pytest.mark.parametrize("extra, says", [
    (["--through-tracker", "--keypoint-noise-m", "-0.01"], "--keypoint-noise-m must be in [0, 1) m, got -0.01"),
    (["--through-tracker", "--keypoint-noise-m", "nan"], "--keypoint-noise-m must be in [0, 1) m, got nan"),
    (["--time-from", "tracker"], "--time-from: only with --through-tracker"),
    (["--keypoint-noise-m", "0.02"], "--keypoint-noise-m: only with --through-tracker"),
])
def test_bad_options_are_one_line_errors(still_library_path, tmp_path, capsys, extra, says) -> None:
    with pytest.raises(SystemExit) as exc:
        eval_main(["recognition", "--library", str(still_library_path), "--quiet", "--plot", str(tmp_path / "r.png"),
                   "--calibration-plot", str(tmp_path / "c.png"), *extra])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]
