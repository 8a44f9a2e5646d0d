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
