"""The planner's config refuses, in one line, values that were tracebacks when the planner was built."""

from __future__ import annotations

import argparse

import pytest

from services.planner.config import CostConfig, PlannerConfig, PlannerServiceConfig
from shared.config import ConfigError, add_config_arguments, resolve_config


def _resolve(argv: list[str]) -> PlannerServiceConfig:
    parser = argparse.ArgumentParser()
    add_config_arguments(parser, "planner", PlannerServiceConfig)
    return resolve_config("planner", PlannerServiceConfig, parser.parse_args(argv), env={})[0]


@pytest.mark.parametrize(("argv", "message"), [
    # a grid of negative size: a numpy traceback
    (["--cost.sdf-resolution", "1e-300"], "planner.cost.sdf_resolution: bad value 1e-300 (must be 0.005-0.5 m)"),
    (["--cost.sdf-resolution", "0.004"], "planner.cost.sdf_resolution: bad value 0.004 (must be 0.005-0.5 m)"),
    (["--cost.sdf-resolution", "2"], "planner.cost.sdf_resolution: bad value 2.0 (must be 0.005-0.5 m)"),
    # a table of 10^299 rows: a torch TypeError traceback
    (["--cost.torso-table-step", "1e-300"],
     "planner.cost.torso_table_step: bad value 1e-300 (must be 0 (off) or >= 0.0001 m)"),
    # torch.set_num_threads: "Overflow when unpacking long"
    (["--threads", "3000000000"], "planner.threads: bad value 3000000000 (must be 0-1024; 0: torch's default)"),
    (["--threads", "1025"], "planner.threads: bad value 1025 (must be 0-1024; 0: torch's default)"),
])
def test_values_that_broke_the_planners_construction_are_refused_in_one_line(argv: list[str], message: str) -> None:
    with pytest.raises(ConfigError) as err:
        _resolve(argv)
    assert str(err.value) == f"{message} (set by {argv[0]})"


def test_the_bounds_and_the_defaults_are_taken() -> None:
    cfg = _resolve(["--cost.sdf-resolution", "0.005", "--cost.torso-table-step", "0", "--threads", "1024"])
    assert cfg.planner.cost.sdf_resolution == 0.005 and cfg.planner.threads == 1024
    _resolve(["--cost.sdf-resolution", "0.5", "--cost.torso-table-step", "0.0001", "--threads", "0"])
    PlannerConfig().validate()
    assert CostConfig().sdf_resolution == 0.02 and CostConfig().torso_table_step == 0.002  # unchanged defaults
    assert PlannerConfig().threads == 1
