"""`foresight --help` and the commands' help texts say what the commands do, in plain text."""

from __future__ import annotations

import re

import pytest

from tools.foresight import SUBCOMMANDS, subcommands
from tools.foresight import main as cli_main


def _choices(command: str, capsys: pytest.CaptureFixture[str]) -> set[str]:
    """The sub-commands ``foresight COMMAND --help`` offers (its usage's ``{a,b,...}``)."""
    try:
        cli_main([command, "--help"])
    except SystemExit:
        pass
    return set(re.findall(r"\{([a-z,-]+)\}", capsys.readouterr().out)[0].split(","))


@pytest.mark.parametrize("command", list(SUBCOMMANDS))
def test_top_level_help_lists_every_subcommand_that_exists(command: str, capsys) -> None:
    """`foresight --help` is generated from the commands' own tables: nothing missing, nothing extra."""
    assert cli_main(["--help"]) == 0
    top = capsys.readouterr().out
    actual = _choices(command, capsys)
    assert actual == set(subcommands(command)) and actual
    for name in actual:
        assert re.search(rf"^ +{name} +\S", top, flags=re.M), name


@pytest.mark.parametrize("argv", [["demo", "--help"], ["bench", "planner", "--help"], ["library", "--help"],
                                  ["train", "--help"], ["eval", "recognition", "--help"], ["eval", "all", "--help"],
                                  ["eval", "interference", "--help"], ["eval", "pace", "--help"]])
def test_help_has_no_rest_markup(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        cli_main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: foresight") and "``" not in out
    assert not re.search(r":(mod|func|class|meth|data|attr):", out)  # eval all printed ':mod:`services...`'


def test_version(capsys) -> None:
    assert cli_main(["--version"]) == 0
    assert re.fullmatch(r"foresight \S+.* \(Python 3\.\d+\.\d+\)\n", capsys.readouterr().out)
    assert cli_main(["-V"]) == 0 and capsys.readouterr().out.startswith("foresight ")
    assert cli_main(["--help"]) == 0  # the usage named --version; the options listed -h alone
    assert "-V, --version" in capsys.readouterr().out


def test_no_command_is_an_error_with_the_help_on_stderr(capsys) -> None:
    from tools.foresight import main

    assert main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "commands:" in err
    assert main(["--help"]) == 0
    assert "commands:" in capsys.readouterr().out


@pytest.mark.parametrize("argv, line", [
    (["eval", "interference", "--quick"],
     "foresight eval interference: error: unrecognized arguments: --quick (--quick is an option of foresight eval "
     "all)"),
    (["log", "render", "x.mcap", "--stp", "3", "--out", "x.png"],
     "foresight log render: error: unrecognized arguments: --stp 3 (did you mean --step?)"),
    (["demo", "--robot-sped", "0.5"], "foresight demo: error: unrecognized arguments: --robot-sped 0.5 (did you mean "
                                      "--robot-speed?)"),
])
def test_a_mistaken_option_is_named_by_its_command_with_what_was_meant(argv, line, capsys) -> None:
    """The top parser used to refuse it (``foresight eval: error: unrecognized arguments: --quick``), no hint."""
    with pytest.raises(SystemExit) as exit_:
        cli_main(argv)
    assert exit_.value.code == 2 and capsys.readouterr().err.strip().splitlines()[-1] == line


def test_a_misspelt_command_gets_the_closest(capsys) -> None:
    assert cli_main(["demoo"]) == 2
    assert "unknown command 'demoo' (did you mean demo? choose from demo, " in capsys.readouterr().err
    assert cli_main(["zzz"]) == 2
    assert "unknown command 'zzz' (choose from demo, " in capsys.readouterr().err


@pytest.mark.parametrize("argv, meant", [(["log", "inf"], "info"), (["eval", "interferenc"], "interference"),
                                         (["library", "infoo"], "info")])
def test_a_misspelt_sub_command_gets_the_closest(argv, meant, capsys) -> None:
    """As the top level's (`foresight demoo`: did you mean demo?); these gave only argparse's "invalid choice"."""
    with pytest.raises(SystemExit) as exit_:
        cli_main(argv)
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert exit_.value.code == 2 and line.startswith(f"foresight {argv[0]}: error: ")
    assert f"invalid choice: {argv[1]!r} (did you mean {meant}? choose from " in line


def test_ctrl_c_finishes_the_progress_bar_before_the_interrupted_line(monkeypatch, tmp_path, capsys) -> None:
    """A new user's Ctrl-C of `foresight train`: the bar was closed only when its loop was collected, after
    "foresight: interrupted", and a half bar was the last thing on the terminal. It ends first, with its count."""
    from services.predictor import train
    from shared.library import save_library
    from shared.synthetic import generate_library

    library = tmp_path / "lib.npz"
    save_library(generate_library(4, 3, seed=1), library)
    fitted: list[int] = []

    def fit(*args: object) -> int:  # the third class's fit is where the Ctrl-C lands
        if len(fitted) == 2:
            raise KeyboardInterrupt
        fitted.append(1)
        return 1

    monkeypatch.setattr(train, "class_fit", fit)
    assert cli_main(["train", "--library", str(library), "--out", str(tmp_path / "m.npz")]) == 130
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-1] == "foresight: interrupted", lines
    assert lines[-2].startswith("GMM per class:") and "| 2/4 [" in lines[-2], lines
