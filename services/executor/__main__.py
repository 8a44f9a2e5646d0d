"""``python -m services.executor`` / ``foresight executor``: simulate the PR2 and log the run to MCAP."""

from __future__ import annotations

import argparse
import sys
import threading

from shared.config import add_config_arguments, resolve_config
from shared.runtime import cli_errors, setup_logging, stop_on_signals

from .core import ExecutorConfig
from .service import ExecutorService

__all__ = ["main"]

DESCRIPTION = """Simulate the PR2 arm following the chosen trajectory of the latest Plan (within its
joint and velocity limits; the plan of replanning step n-1 runs during step n), publish RobotState,
hold the robot when plans or predictions go stale, and log every message under the key prefix to an
MCAP file (plus Foxglove 3D channels). In lock-step mode the executor is the simulation master and
emits the ClockTicks. Stops after --steps, or on SIGINT/SIGTERM (the MCAP file is finalised either
way). Options come from the dataclass defaults < --config FILE ([executor], [zenoh]) < env
FORESIGHT_EXECUTOR_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def main(argv: list[str] | None = None, prog: str = "python -m services.executor") -> int:
    """Run the executor; returns the exit status (0 done or stopped, 2 bad input)."""
    parser = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    add_config_arguments(parser, "executor", ExecutorConfig)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, zcfg = resolve_config("executor", ExecutorConfig, args)
        setup_logging(cfg.log_level)
        stop = threading.Event()
        restore = stop_on_signals(stop)
        try:
            service = ExecutorService(cfg, zcfg, stop)
            result = service.run()
        finally:
            restore()
    if result.mcap_path:
        print(f"mcap: {result.mcap_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
