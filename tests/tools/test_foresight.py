"""`foresight --help` and the commands' help texts say what the commands do, in plain text."""

from __future__ import annotations

import re

import pytest

from tools.foresight import COMMANDS
from tools.foresight import main as cli_main


def test_log_command_lists_its_subcommands(capsys) -> None:
    from tools.log.cli import main as log_main

    with pytest.raises(SystemExit):
        log_main(["--help"])
    subcommands = set(re.findall(r"\{([a-z,]+)\}", capsys.readouterr().out)[0].split(","))
    assert subcommands == {"info", "render", "latency"}
    for name in subcommands:
        assert f"({name})" in COMMANDS["log"][1]


@pytest.mark.parametrize("argv", [["demo", "--help"], ["bench", "planner", "--help"], ["library", "--help"],
                                  ["train", "--help"], ["eval", "recognition", "--help"]])
def test_help_has_no_rest_markup(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        cli_main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: foresight") and "``" not in out
