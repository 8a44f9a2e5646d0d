"""``foresight log table``: the step table of a logged run, as the demo prints it (two lock-step steps here)."""

from __future__ import annotations

import json

import pytest

from tools.log.cli import main


def test_the_table_has_a_row_per_step_and_the_outcome(run_log, capsys) -> None:
    assert main(["table", str(run_log)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[:4] == ["step", "t", "(s)", "chosen"]
    assert lines[1].split()[:5] == ["0", "0.00", "blue_cup", "1.500", "4.000"]
    assert lines[2].split()[:5] == ["1", "0.20", "red_cup", "5.000", "1.200"]
    assert lines[3] == "switch step: 1 (t = 0.20 s)"
    assert lines[4] == "goal reached: no" and lines[5].startswith("interference cost")
    assert main(["table", str(run_log), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["chosen_goal_per_step"] == ["blue_cup", "red_cup"] and summary["switch_step"] == 1


def test_a_log_without_plans_is_one_clear_error(tmp_path, capsys) -> None:
    from shared.protocol import Keys
    from shared.recording.writer import McapLog

    path = tmp_path / "empty.mcap"
    McapLog(path, Keys()).close()
    with pytest.raises(SystemExit) as exc:
        main(["table", str(path)])
    assert exc.value.code == 2
    assert "no plans logged" in capsys.readouterr().err
