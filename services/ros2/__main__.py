"""``python -m services.ros2`` / ``foresight ros2``: Foresight's run as ROS 2 topics over rmw_zenoh."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.runtime import lower_priority, service_main
from shared.security.acl import refuse_ros2_keys

from .service import Ros2Service, Ros2ServiceConfig

__all__ = ["main"]

DESCRIPTION = """Publish Foresight's plans, robot state, predicted occupancy, human and class posterior as
ROS 2 topics the way rmw_zenoh does (CDR payloads on <domain>/<topic>/<type>/<hash> keys, the rmw_zenoh
attachment, graph liveliness tokens), so that `ros2 topic echo` and RViz see them with no bridge and no
ROS installation here. Connect it to the router the ROS 2 nodes use (rmw_zenoh's zenohd, tcp/...:7447)
and to Foresight's (the same router, or --connect both). docs/ros2.md has the topics and a walk-through.
Options: defaults < --config FILE ([ros2], [zenoh]) < env FORESIGHT_ROS2_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def _make(cfg: Ros2ServiceConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    refuse_ros2_keys(zcfg.security_dir, "foresight ros2")
    service = Ros2Service(cfg, zcfg)
    lower_priority(cfg.nice)  # this process only (the gateway as `foresight ros2`)
    return lambda: service.run(stop)


def main(argv: list[str] | None = None, prog: str = "python -m services.ros2") -> int:
    """Run the ROS 2 gateway; returns the exit status (0 stopped, 2 bad input)."""
    return service_main(argv, prog, section="ros2", config_cls=Ros2ServiceConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
