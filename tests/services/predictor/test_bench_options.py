"""``foresight bench predictor``: a bad option is one line, before the quick model is trained."""

from __future__ import annotations

import pytest

from services.predictor import bench


@pytest.mark.parametrize("option", ["--grid", "--demos", "--repeats"])
@pytest.mark.parametrize("value", ["0", "-3"])
def test_a_count_below_one_is_one_line_before_training(option, value, monkeypatch, capsys) -> None:
    def train(*_args, **_kwargs):
        raise AssertionError("the quick model was trained before the options were checked")

    monkeypatch.setattr(bench, "train_model", train)
    with pytest.raises(SystemExit) as exc:
        bench.main([option, value])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err == f"foresight bench predictor: error: {option} must be at least 1, got {value}"
