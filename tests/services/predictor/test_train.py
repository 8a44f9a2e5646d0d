"""``foresight train``'s trainer (services/predictor/train.py): what it shows while it works."""

from __future__ import annotations

from services.predictor.train import train_model

from .conftest import _FITS, SMALL


def test_training_progress_in_a_log_is_whole_lines(small_library, scene, capsys) -> None:
    """`make demo > demo.log` on a first run: each of training's bars was one line of frames joined by carriage
    returns (a review)."""
    train_model(small_library, scene, SMALL, progress=True, fit_cache=dict(_FITS))
    err = capsys.readouterr().err
    assert "GMM per class" in err and "volumes" in err and "\r" not in err


def test_train_writes_its_model_into_directories_it_creates(tmp_path, capsys) -> None:
    """A new user's first hour: `foresight train --out DIR/model` with DIR not there yet. The directories are made
    (before the training: a file in their way is said at once), and --help says so."""
    import pytest

    from services.predictor.model import PredictionModel
    from services.predictor.train import main
    from shared.library import save_library
    from shared.synthetic import generate_library

    library, out = tmp_path / "lib.npz", tmp_path / "new" / "dir" / "model"
    save_library(generate_library(n_classes=2, n_demos=4, seed=3), library)
    assert main(["--library", str(library), "--out", str(out), "--components", "2", "--temperature", "1",
                 "--quiet"]) == 0
    assert PredictionModel.load(out).n_classes == 2
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "missing directories are created" in " ".join(capsys.readouterr().out.split())


def test_train_calibrates_the_novelty_threshold_for_a_sensor_s_noise_and_says_so(tmp_path, capsys) -> None:
    """`foresight train --sensor-noise-m 0.02`: the model holds the noise its novelty threshold was calibrated for,
    and the command's last line says it."""
    from services.predictor.model import PredictionModel
    from services.predictor.train import main
    from shared.library import save_library
    from shared.synthetic import generate_library

    library = tmp_path / "lib.npz"
    save_library(generate_library(n_classes=2, n_demos=4, seed=3), library)
    common = ["--library", str(library), "--components", "2", "--temperature", "1", "--quiet"]
    assert main([*common, "--out", str(tmp_path / "clean.npz")]) == 0
    assert main([*common, "--out", str(tmp_path / "noisy.npz"), "--sensor-noise-m", "0.02"]) == 0
    clean, noisy = (PredictionModel.load(tmp_path / f"{n}.npz").novelty for n in ("clean", "noisy"))
    assert clean.sensor_noise_m == 0.0 and noisy.sensor_noise_m == 0.02 and noisy.threshold < clean.threshold
    assert "with 2 cm of noise per axis, fitted back as the tracker does" in capsys.readouterr().out


def test_a_model_cache_keyed_on_the_training_options_tells_a_sensor_s_noise_apart() -> None:
    """The demo's and the experiments' caches key on ``repr(TrainConfig)``: a model calibrated for a sensor is another
    model, and one calibrated as before keeps the key it had (no sensor_noise_m in it)."""
    from dataclasses import replace

    from services.predictor.train import TrainConfig

    assert "sensor_noise_m" not in repr(TrainConfig()) and repr(TrainConfig()).startswith("TrainConfig(gmm=")
    assert repr(replace(TrainConfig(), sensor_noise_m=0.02)) == repr(TrainConfig())[:-1] + ", sensor_noise_m=0.02)"
