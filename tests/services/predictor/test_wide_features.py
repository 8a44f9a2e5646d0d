"""A 16-feature library: train and eval recognition work; the occupancy commands refuse it in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.predictor.core import PredictorCore
from services.predictor.features import FeatureEncoder
from services.predictor.gmm import GMMConfig
from services.predictor.model import ModelError, PredictionModel
from services.predictor.recognition import leave_one_out
from services.predictor.recognition import main as eval_main
from services.predictor.train import TrainConfig, train_model
from services.predictor.train import main as train_main
from services.replayer.core import ReplayerConfig, select_demos
from shared.feature_sets import MappingError
from shared.library import MotionLibrary, save_library
from shared.synthetic_wide import WIDE_FEATURE_NAMES, generate_wide_library


@pytest.fixture(scope="module")
def wide() -> MotionLibrary:
    return generate_wide_library(n_classes=3, n_demos=6, seed=4)


@pytest.fixture(scope="module")
def wide_model(wide, scene) -> PredictionModel:
    return train_model(wide, scene, TrainConfig(gmm=GMMConfig(n_components=3, max_iter=30)), progress=False)


@pytest.fixture(scope="module")
def wide_path(wide, tmp_path_factory):
    path = tmp_path_factory.mktemp("wide") / "wide.npz"
    save_library(wide, path)
    return path


def test_encoder_takes_any_feature_count(wide) -> None:
    enc = FeatureEncoder("paper", feature_names=WIDE_FEATURE_NAMES)
    x = enc.batch(wide.demos[0].features)
    assert enc.dim == 17 and x.shape == (100, 17) and enc.posture_columns() == slice(1, 17)
    enc.reset()
    np.testing.assert_array_equal(enc.step(wide.demos[0].features[3], 3), x[3])
    with pytest.raises(MappingError, match="feature variant 'hand' needs the herakles feature set"):
        FeatureEncoder("hand", feature_names=WIDE_FEATURE_NAMES)


def test_train_writes_a_recognition_only_model(wide, wide_model, scene, tmp_path) -> None:
    assert wide_model.volumes is None and wide_model.feature_names == WIDE_FEATURE_NAMES
    assert wide_model.motions.shape[0] == 3 and wide_model.motions.shape[2] == 16
    assert wide_model.means.shape[2] == 17
    wide_model.save(tmp_path / "m.npz")
    back = PredictionModel.load(tmp_path / "m.npz")
    assert back.volumes is None and back.feature_names == WIDE_FEATURE_NAMES
    np.testing.assert_array_equal(back.means, wide_model.means)
    # it recognises: the summed log-likelihood of a whole demonstration picks its own class
    bank = back.bank()
    enc = back.encoder()
    picks = [int(np.argmax(bank.log_likelihood(enc.batch(d.features)).sum(axis=0))) for d in wide.demos]
    assert picks == [d.label for d in wide.demos]


def test_the_predictor_refuses_a_model_without_volumes(wide_model, scene) -> None:
    with pytest.raises(ModelError) as exc:
        PredictorCore(wide_model, scene)
    msg = str(exc.value)
    assert "\n" not in msg and "needs a model with swept volumes" in msg
    assert "16 features (pelvis_x .. r_hand_roll) have no mapping to the human model (known: herakles)" in msg


def test_the_replayer_refuses_a_library_without_the_herakles_features(wide) -> None:
    with pytest.raises(MappingError) as exc:
        select_demos(wide, ReplayerConfig())
    assert "\n" not in str(exc.value) and "foresight replayer (HumanPose messages) needs the herakles" in str(exc.value)


def test_leave_one_out_on_16_features(wide) -> None:
    res = leave_one_out(wide, GMMConfig(n_components=3, max_iter=30), n_jobs=1, progress=False)
    assert res.log_likelihood.shape == (18, 10, 3)
    assert res.rates[-1] >= 0.8 and res.rates[-1] >= res.rates[0]


def test_cli_train_and_eval_on_16_features(wide_path, tmp_path, capsys) -> None:
    out = tmp_path / "m.npz"
    assert train_main(["--library", str(wide_path), "--out", str(out), "--components", "2", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "no swept volumes: 16 features without a mapping to the human model" in printed
    assert eval_main(["recognition", "--library", str(wide_path), "--components", "2", "--n-jobs", "1", "--json",
                      "--quiet", "--plot", str(tmp_path / "r.png"), "--calibration-plot", str(tmp_path / "c.png"),
                      "--temperatures", "1,10"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["n_features"] == 16 and len(data["recognition_rates"]) == 10
    with pytest.raises(SystemExit) as exc:
        train_main(["--library", str(wide_path), "--out", str(out), "--features", "relative", "--quiet"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "feature variant 'relative' needs the herakles feature set" in err[0]


def test_predictor_service_cli_refuses_in_one_line(wide_model, tmp_path, capsys) -> None:
    from services.predictor.__main__ import main as predictor_main

    wide_model.save(tmp_path / "m.npz")
    with pytest.raises(SystemExit) as exc:
        predictor_main(["--model", str(tmp_path / "m.npz"), "--listen", "tcp/127.0.0.1:0", "--no-multicast-scouting"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "needs a model with swept volumes" in err[0]


def test_model_files_without_feature_names_are_the_papers(paper_model, tmp_path) -> None:
    paper_model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    assert tuple(arrays.pop("feature_names").tolist()) == paper_model.feature_names
    np.savez(tmp_path / "old.npz", **arrays)  # a file written before feature_names existed
    old = PredictionModel.load(tmp_path / "old.npz")
    assert old.feature_names == paper_model.feature_names and old.volumes is not None
    np.testing.assert_array_equal(old.volumes, paper_model.volumes)
    del arrays["volumes"]  # the paper's features have a mapping: the volumes must be there
    np.savez(tmp_path / "broken.npz", **arrays)
    with pytest.raises(ModelError, match="inconsistent.*volumes"):
        PredictionModel.load(tmp_path / "broken.npz")
