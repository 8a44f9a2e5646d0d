"""`foresight --help` and the commands' help texts say what the commands do, in plain text."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from shared.cli import COMMANDS
from shared.cli import main as cli_main

REPO = Path(__file__).resolve().parents[2]


def test_log_command_lists_its_subcommands(capsys) -> None:
    from shared.logtools import main as log_main

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


def test_protocol_doc_names_every_liveliness_token() -> None:
    declared = set()
    for path in [*REPO.glob("services/**/*.py"), *REPO.glob("shared/**/*.py")]:
        # the service name is Presence's third positional argument (keywords may follow)
        declared |= set(re.findall(r'Presence\(\s*\w+,\s*[\w.]+,\s*"([a-z_]+)"', path.read_text()))
    assert {"replayer", "predictor", "planner", "executor", "demo"} <= declared
    doc = (REPO / "docs" / "protocol.md").read_text()
    line = next(ln for ln in doc.splitlines() if ln.startswith("Service names:"))
    named = set(re.findall(r"`([a-z_]+)`", line))
    assert declared == named, (declared, named)


SERVICE_CONFIGS = {
    "replayer": "services.replayer.core:ReplayerConfig",
    "predictor": "services.predictor.core:PredictorConfig",
    "planner": "services.planner.config:PlannerServiceConfig",
    "executor": "services.executor.core:ExecutorConfig",
}


@pytest.mark.parametrize("service", sorted(SERVICE_CONFIGS))
def test_service_help_shows_every_option_of_its_config_tree(service, capsys) -> None:
    """One flag per field of the section's tree (nested configs as --<table>.<name>), each with a help text."""
    import importlib

    from shared.config import config_options

    module, cls_name = SERVICE_CONFIGS[service].split(":")
    options = config_options(service, getattr(importlib.import_module(module), cls_name))
    main = importlib.import_module(f"services.{service}.__main__").main
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for o in options:
        assert o.help, f"{o.name} has no help text"
        assert re.search(rf"^\s+{re.escape(o.flag)}\b", out, re.M), f"{o.flag} ({o.name}) missing from --help"
    tables = {o.table for o in options}
    for table in tables:
        assert f"[{'.'.join(table)}] options (env FORESIGHT_{'_'.join(table).upper()}_<NAME>" in out
    if service == "planner":
        assert {("planner",), ("planner", "stomp"), ("planner", "cost")} == tables
        assert "--stomp.iterations" in out and "--cost.w-human" in out
    assert ":meth:" not in out and "``" not in out  # docstring markup is made plain
