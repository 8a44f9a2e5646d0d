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


def test_training_as_before_keeps_its_cache_key_and_file_and_time_from_tracker_is_another() -> None:
    """``time_from`` at its default (``recording``) is not in ``repr(TrainConfig)``: the demo's replayer model keeps
    its key; ``tracker`` is another key."""
    from dataclasses import replace

    from services.predictor.train import TrainConfig

    assert "time_from" not in repr(TrainConfig())
    assert repr(replace(TrainConfig(), time_from="recording")) == repr(TrainConfig())
    assert repr(replace(TrainConfig(), time_from="tracker")) == repr(TrainConfig())[:-1] + ", time_from='tracker')"


def test_time_from_tracker_trains_on_each_demonstration_from_where_the_tracker_would_start_its_reach(
        small_library, scene, tmp_path) -> None:
    """A live reach's first pose is index 0 and comes 8-30 samples into a demonstration as recorded (a review): with
    ``time_from="tracker"`` the mixtures are those of the demonstrations cut at the tracker's reach rule's start, the
    model says so, and its file keeps it (a file without it, or a model trained as before: ``recording``)."""
    from dataclasses import replace

    import numpy as np
    import pytest

    from services.predictor.model import ModelError, PredictionModel
    from services.tracker.core import TrackerConfig
    from services.tracker.reach import recorded_start

    starts = [recorded_start(d.features, TrackerConfig()) for d in small_library.demos]
    assert min(starts) > 0
    cut = replace(small_library, demos=[replace(d, features=d.features[s:]) for d, s in zip(small_library.demos,
                                                                                           starts, strict=True)])
    cfg, fits = replace(SMALL, temperature=1.0), dict(_FITS)
    tracker = train_model(small_library, scene, replace(cfg, time_from="tracker"), progress=False, fit_cache=fits)
    as_cut = train_model(cut, scene, cfg, progress=False, fit_cache=fits)
    before = train_model(small_library, scene, cfg, progress=False, fit_cache=fits)
    np.testing.assert_array_equal(tracker.means, as_cut.means)
    assert not np.array_equal(tracker.means, before.means)
    assert tracker.last_index == max(d.n_samples - s for d, s in zip(small_library.demos, starts, strict=True)) - 1
    assert (tracker.time_from, as_cut.time_from) == ("tracker", "recording")
    assert "tracker's reach rule" in tracker.describe_time() and "first sample" in before.describe_time()
    tracker.save(tmp_path / "t.npz")
    before.save(tmp_path / "b.npz")
    assert PredictionModel.load(tmp_path / "t.npz").time_from == "tracker"
    with np.load(tmp_path / "b.npz") as z:
        assert "time_from" not in z.files  # a model trained as before is the same file
    with np.load(tmp_path / "t.npz") as z:
        arrays = dict(z)
    np.savez(tmp_path / "old.npz", **{k: v for k, v in arrays.items() if k != "time_from"})
    assert PredictionModel.load(tmp_path / "old.npz").time_from == "recording"
    np.savez(tmp_path / "bad.npz", **{**arrays, "time_from": np.array("sensor")})
    with pytest.raises(ModelError, match="time_from 'sensor' is not one of recording, tracker"):
        PredictionModel.load(tmp_path / "bad.npz")


def test_train_time_from_tracker_says_so(tmp_path, capsys) -> None:
    """``foresight train --time-from tracker`` writes such a model and its output line says where time starts."""
    from services.predictor.model import PredictionModel
    from services.predictor.train import main
    from shared.library import save_library
    from shared.synthetic import generate_library

    library = tmp_path / "lib.npz"
    save_library(generate_library(n_classes=2, n_demos=4, seed=3), library)
    assert main(["--library", str(library), "--components", "2", "--temperature", "1", "--quiet", "--out",
                 str(tmp_path / "m.npz"), "--time-from", "tracker"]) == 0
    assert PredictionModel.load(tmp_path / "m.npz").time_from == "tracker"
    assert "time from where the tracker's reach rule starts each demonstration" in capsys.readouterr().out
