"""The command line's parser: a mistake is named in the sub-command it was made in, with the closest option."""

from __future__ import annotations

import pytest

from shared.arguments import ArgumentParser


def tool() -> ArgumentParser:
    """``tool eval {all,interference}`` and ``tool log render``, as the CLI nests its commands."""
    top = ArgumentParser(prog="tool")
    top.add_argument("--log-level")
    commands = top.add_subparsers(dest="command", required=True)
    evals = commands.add_parser("eval", prog="tool eval").add_subparsers(dest="what", required=True)
    evals.add_parser("all", prog="tool eval all").add_argument("--quick", action="store_true")
    evals.add_parser("interference", prog="tool eval interference").add_argument("--robot-speed", type=float)
    commands.add_parser("render", prog="tool render").add_argument("--step", type=int)
    return top


def refusal(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exit_:
        tool().parse_args(argv)
    assert exit_.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


def test_a_misspelt_option_is_refused_by_its_sub_command_with_the_closest_one(capsys) -> None:
    assert refusal(["eval", "interference", "--robot-sped", "0.5"], capsys) == (
        "tool eval interference: error: unrecognized arguments: --robot-sped 0.5 (did you mean --robot-speed?)")
    assert refusal(["render", "--stp=3"], capsys).endswith("--stp=3 (did you mean --step?)")


def test_an_option_of_a_sibling_command_names_the_sibling(capsys) -> None:
    assert refusal(["eval", "interference", "--quick"], capsys) == (
        "tool eval interference: error: unrecognized arguments: --quick (--quick is an option of tool eval all)")


def test_an_argument_nothing_resembles_points_to_the_commands_help(capsys) -> None:
    assert refusal(["render", "extra"], capsys) == (
        "tool render: error: unrecognized arguments: extra (see tool render --help)")
    assert refusal(["--bogus", "render"], capsys).startswith("tool: error: unrecognized arguments: --bogus")


def test_arguments_it_knows_parse_as_argparse_parses_them() -> None:
    ns = tool().parse_args(["--log-level", "DEBUG", "eval", "interference", "--robot-speed", "0.25"])
    assert (ns.log_level, ns.command, ns.what, ns.robot_speed) == ("DEBUG", "eval", "interference", 0.25)


def test_an_option_given_to_the_parent_command_is_the_parents_mistake(capsys) -> None:
    """``foresight log --bogus info x.mcap`` was blamed on ``foresight log info``."""
    assert refusal(["eval", "--bogus", "all"], capsys) == (
        "tool eval: error: unrecognized arguments: --bogus (see tool eval --help)")


def test_an_option_is_never_abbreviated_and_a_mistake_is_one_line(capsys) -> None:
    """`--compar` ran `--compare`'s three runs (argparse takes a unique prefix), and a misspelt option printed the
    command's whole usage (18 lines for `foresight demo`) before the line that said what was wrong (a review)."""
    with pytest.raises(SystemExit) as exit_:
        tool().parse_args(["eval", "interference", "--robot-spe", "0.5"])
    assert exit_.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == ("tool eval interference: error: unrecognized arguments: --robot-spe 0.5 (did you mean "
                    "--robot-speed?)")
    with pytest.raises(SystemExit):
        tool().parse_args(["render", "--step", "x"])
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == "tool render: error: argument --step: invalid int value: 'x'"
    assert tool().parse_args(["eval", "interference", "--robot-speed", "0.5"]).robot_speed == 0.5


@pytest.mark.parametrize("argv", [["security", "init", ""], ["eval", "all", "--quick", "--out", " "],
                                  ["eval", "pace", "--plot", ""], ["log", "render", "x.mcap", "--all", "--out", ""]])
def test_an_empty_path_on_the_command_line_is_refused(argv, tmp_path, monkeypatch, capsys) -> None:
    """It was the working directory: `security init ''` wrote the authority's key there, `log render --all --out ''`
    its PNGs, `eval all --out ''` started its run (a review)."""
    from tools.foresight import main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert ": error: argument " in line and "empty; give a path (an empty one would be the current directory)" in line
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("argv, hint", [(["demo", "--bogus"], "(see foresight demo --help)"),
                                        (["train", "--bogus"], "(see foresight train --help)"),
                                        (["demo", "--stepz", "3"], "(did you mean --steps?)")])
def test_a_hint_only_for_an_option_close_in_its_name_not_in_the_dashes_every_one_has(argv, hint, capsys) -> None:
    """`foresight demo --bogus` said "did you mean --ros2?": the two share "--", "o" and "s"."""
    from tools.foresight import main as cli_main

    with pytest.raises(SystemExit):
        cli_main(argv)
    assert capsys.readouterr().err.strip().endswith(hint)


def test_a_misspelt_sub_command_or_choice_gets_the_closest(capsys) -> None:
    """`foresight demoo` said "did you mean demo?", `foresight eval interferenc` only argparse's "invalid choice"."""
    assert refusal(["eval", "interferenc"], capsys).endswith(
        "invalid choice: 'interferenc' (did you mean interference? choose from all, interference)")
    assert refusal(["evl", "all"], capsys).endswith(
        "invalid choice: 'evl' (did you mean eval? choose from eval, render)")
    picky = ArgumentParser(prog="tool")
    picky.add_argument("--mode", choices=("lockstep", "realtime"))
    with pytest.raises(SystemExit):
        picky.parse_args(["--mode", "lockstp"])
    assert "invalid choice: 'lockstp' (did you mean lockstep? choose from " in capsys.readouterr().err
    assert refusal(["eval", "zzz"], capsys).endswith("invalid choice: 'zzz' (choose from 'all', 'interference')")


def test_mode_where_a_command_has_only_the_zenoh_mode_points_to_it(capsys) -> None:
    """``foresight view --mode client`` said only "unrecognized arguments": the session's mode is ``--zenoh-mode``."""
    view = ArgumentParser(prog="foresight view")
    view.add_argument("--zenoh-mode")
    view.add_argument("--model")  # closer to --mode in spelling than --zenoh-mode: the session's mode still wins
    with pytest.raises(SystemExit):
        view.parse_args(["--mode", "client"])
    assert capsys.readouterr().err.strip() == (
        "foresight view: error: unrecognized arguments: --mode client (did you mean --zenoh-mode?)")
