"""``python -m services.replayer`` / ``foresight replayer``: stream a motion library over Zenoh."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.runtime import service_main

from .core import ReplayerConfig
from .service import ReplayerService

__all__ = ["main"]

DESCRIPTION = """Stream the demonstrations of a human-motion library as HumanPose messages, with
DemoMarker start/end around each demonstration: in real time at --rate-hz, or --samples-per-tick
poses per ClockTick in lock-step mode. Stops after the selection (unless --loop) or on SIGINT/SIGTERM.
Options come from the dataclass defaults < --config FILE ([replayer], [zenoh]) < env
FORESIGHT_REPLAYER_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def _make(cfg: ReplayerConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    service = ReplayerService(cfg, zcfg)
    return lambda: service.run(stop)


def main(argv: list[str] | None = None, prog: str = "python -m services.replayer") -> int:
    """Run the replayer; returns the exit status (0 done or stopped, 2 bad input)."""
    return service_main(argv, prog, section="replayer", config_cls=ReplayerConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
