"""``python -m services.replayer`` / ``foresight replayer``: stream a motion library over Zenoh."""

from __future__ import annotations

import argparse
import sys
import threading

from shared.config import add_config_arguments, resolve_config
from shared.runtime import cli_errors, setup_logging, stop_on_signals

from .core import ReplayerConfig
from .service import ReplayerService

__all__ = ["main"]

DESCRIPTION = """Stream the demonstrations of a human-motion library as HumanPose messages, with
DemoMarker start/end around each demonstration: in real time at --rate-hz, or --samples-per-tick
poses per ClockTick in lock-step mode. Stops after the selection (unless --loop) or on SIGINT/SIGTERM.
Options come from the dataclass defaults < --config FILE ([replayer], [zenoh]) < env
FORESIGHT_REPLAYER_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def main(argv: list[str] | None = None, prog: str = "python -m services.replayer") -> int:
    """Run the replayer; returns the exit status (0 done or stopped, 2 bad input)."""
    parser = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    add_config_arguments(parser, "replayer", ReplayerConfig)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, zcfg = resolve_config("replayer", ReplayerConfig, args)
        setup_logging(cfg.log_level)
        service = ReplayerService(cfg, zcfg)
        stop = threading.Event()
        restore = stop_on_signals(stop)
        try:
            service.run(stop)
        finally:
            restore()
    return 0


if __name__ == "__main__":
    sys.exit(main())
