"""``python -m services.planner`` / ``foresight planner``: multi-goal STOMP around the predicted occupancy."""

from __future__ import annotations

import argparse
import sys
import threading

from shared.config import add_config_arguments, resolve_config
from shared.runtime import cli_errors, setup_logging, stop_on_signals

from .service import PlannerService, PlannerServiceConfig

__all__ = ["main"]

DESCRIPTION = """Plan the robot's motion to every goal (a grasp at each cup) at once with batched STOMP,
around the predicted human occupancy, and publish the K candidates with the least-cost one chosen
(Algorithm 1 of Mainprice & Berenson 2013). Real-time: one plan every --period-s; lock-step: one plan
per ClockTick. Options come from the dataclass defaults < --config FILE ([planner], [zenoh]) < env
FORESIGHT_PLANNER_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def main(argv: list[str] | None = None, prog: str = "python -m services.planner") -> int:
    """Run the planner service until SIGINT/SIGTERM; returns the exit status (2: bad input)."""
    parser = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    add_config_arguments(parser, "planner", PlannerServiceConfig)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, zcfg = resolve_config("planner", PlannerServiceConfig, args)
        setup_logging(cfg.log_level)
        service = PlannerService(cfg, zcfg)
    stop = threading.Event()
    restore = stop_on_signals(stop)
    try:
        service.run(stop)
    finally:
        restore()
    return 0


if __name__ == "__main__":
    sys.exit(main())
