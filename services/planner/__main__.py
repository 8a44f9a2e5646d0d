"""``python -m services.planner`` / ``foresight planner``: multi-goal STOMP around the predicted occupancy."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.runtime import service_main

from .config import PlannerServiceConfig  # the service (torch, its compiler) is imported to run, not for --help

__all__ = ["main"]

DESCRIPTION = """Plan the robot's motion to every goal (a grasp at each cup) at once with batched STOMP,
around the predicted human occupancy, and publish the K candidates with the least-cost one chosen
(Algorithm 1 of Mainprice & Berenson 2013). Real-time: a plan for each new prediction and whenever the
robot leaves its plan, at least one every --period-s (--trigger period: one every --period-s only); lock-step:
one plan per ClockTick. Options come from the dataclass defaults < --config FILE ([planner], [planner.stomp],
[planner.cost], [zenoh]) < env FORESIGHT_PLANNER_<NAME>, FORESIGHT_PLANNER_STOMP_<NAME>,
FORESIGHT_PLANNER_COST_<NAME>, FORESIGHT_ZENOH_<NAME> < flags (--<name>, --stomp.<name>, --cost.<name>)."""


def _make(cfg: PlannerServiceConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    from .service import PlannerService

    service = PlannerService(cfg, zcfg)
    return lambda: service.run(stop)


def main(argv: list[str] | None = None, prog: str = "python -m services.planner") -> int:
    """Run the planner service until SIGINT/SIGTERM; returns the exit status (2: bad input)."""
    return service_main(argv, prog, section="planner", config_cls=PlannerServiceConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
