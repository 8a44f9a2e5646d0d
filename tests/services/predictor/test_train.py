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
