"""``python -m services.executor`` / ``foresight executor``: simulate the PR2 and log the run to MCAP."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.runtime import service_main

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


def _make(cfg: ExecutorConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    service = ExecutorService(cfg, zcfg, stop)

    def run() -> None:
        result = service.run()
        if result.mcap_path:
            print(f"mcap: {result.mcap_path}")

    return run


def main(argv: list[str] | None = None, prog: str = "python -m services.executor") -> int:
    """Run the executor; returns the exit status (0 done or stopped, 2 bad input)."""
    return service_main(argv, prog, section="executor", config_cls=ExecutorConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
