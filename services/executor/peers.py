"""What the executor does when a service of the run appears or disappears (its liveliness token).

Real time: the core notes it (``ExecutorCore.note_peer``: the robot holds while a service of ``hold_without`` is
gone) and a change is logged; a recording's source (``recorded_sources``) ending its stream after its end marker is
no fault, a live tracker going is. Lock-step: the clock protocol decides, and a liveliness event's timing must not
change a lock-step run, so nothing is acted on; but a service gone mid-run is said, with what follows (each tick
waits ``lockstep_timeout_s`` for it): before, a compose run whose planner was killed went quiet for 30 s a tick and
ended as if nothing had happened.
"""

from __future__ import annotations

import logging
from typing import Any

from .config import ExecutorConfig

__all__ = ["PeerWatch", "LOCKSTEP_INPUTS"]

log = logging.getLogger("foresight.executor")

LOCKSTEP_INPUTS = ("planner", "predictor")
"""The services whose output a lock-step tick waits for (the plan; the prediction with ``require_occupancy``): one
gone is said. Others (a ROS 2 gateway, a view, a watcher) may come and go without a tick waiting for them."""


class PeerWatch:
    """The executor's reaction to the run's services coming and going.

    Args:
        config: The executor's options (its mode, ``hold_without``, ``lockstep_timeout_s``).

    Attributes:
        gone_lockstep: Services gone mid-run in lock-step (said, not acted on).
    """

    def __init__(self, config: ExecutorConfig) -> None:
        self.config = config
        self.gone_lockstep: set[str] = set()

    def note(self, service: str, alive: bool, core: Any) -> None:
        """``service`` appeared (``alive``) or disappeared; ``core``: the executor's core (or robot arm) now."""
        if self.config.mode == "lockstep":
            if service in LOCKSTEP_INPUTS:  # what a tick waits for (the human's source ends its stream by design)
                self._say_lockstep(service, alive)
            return
        was_gone = service in core.gone
        if core.note_peer(service, alive):  # a recording ending its stream after its end marker is no fault
            log.info("executor: %s ended its stream after the demonstration's end: the robot goes on", service)
        elif (service in core.gone) != was_gone:
            log.warning("executor: %s %s", service, "is back" if alive else "is gone: holding the robot")

    def _say_lockstep(self, service: str, alive: bool) -> None:
        if not alive and service not in self.gone_lockstep:
            self.gone_lockstep.add(service)
            log.warning("executor: %s is gone: each tick now waits up to %.0f s for what it publishes and goes on "
                        "without it (start it again: it rejoins)", service, self.config.lockstep_timeout_s)
        elif alive and service in self.gone_lockstep:
            self.gone_lockstep.discard(service)
            log.info("executor: %s is back", service)
