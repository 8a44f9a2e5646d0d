"""`foresight eval interference|switch`: counts and seeds out of range are one line, before any model is trained."""

from __future__ import annotations

import pytest

from services.experiments.cli import main


@pytest.mark.parametrize(("argv", "message"), [
    (["interference", "--demos", "-1"], "--demos and --seeds must be >= 1, got -1 and 10"),
    (["interference", "--demos", "0"], "--demos and --seeds must be >= 1, got 0 and 10"),
    (["interference", "--seeds", "0"], "--demos and --seeds must be >= 1, got 5 and 0"),
    (["switch", "--demos", "-3"], "--demos must be >= 0 (0: all) and --seed >= 0, got -3 and 0"),
    (["switch", "--seed", "-1"], "--demos must be >= 0 (0: all) and --seed >= 0, got 0 and -1"),
])
def test_counts_and_seeds_out_of_range_are_one_line(tmp_path, capsys, argv, message) -> None:
    """They were a numpy traceback, a table of NaN, every demonstration, or a minute's stall per failed step."""
    with pytest.raises(SystemExit) as stop:
        main([*argv, "--models-dir", str(tmp_path / "models"), "--work-dir", str(tmp_path / "work")])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "models").exists()  # refused before training
