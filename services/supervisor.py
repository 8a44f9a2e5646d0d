"""Watching a run's service processes: a service that dies is reported once and the run carries on.

The executor holds the robot while the predictor, the planner or (mid-demonstration) the human's source is
gone (its ``hold_without``) or its inputs are stale, so one dead service is a fault to report, not a
reason to abort the run. With ``restart`` the supervisor starts it again (at most ``max_restarts``
times per service), and the executor resumes once the service's outputs are fresh. A lock-step run
(``fatal``) is different: every tick waits for every service's output, so without the dead service it
would crawl on at one timeout a tick; its death ends the run, its log complete.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

from services.processes import ServiceProcess, describe_exit
from shared.protocol import HUMAN_SOURCES

__all__ = ["Supervisor", "describe_exit"]

log = logging.getLogger("foresight.supervisor")


class Supervisor:
    """Reports (and optionally restarts) the services of a run that exit before it ends.

    Args:
        procs: The run's processes by service name.
        out: Where to say it (one line per event).
        restart: Start a dead service again.
        max_restarts: Restarts per service at most.
        expected: Services whose exit with status 0 is their normal end (the human's source: its stream ends).
        fatal: A service that dies and is not started again ends the run (:attr:`fatal_fault`): in lock-step
            every tick waits for every service's output, so the run would only crawl on, one timeout a tick.

    Attributes:
        faults: ``(service, exit status)`` of every death.
        fatal_fault: With ``fatal``, the service whose death ends the run (None while none did).
    """

    def __init__(self, procs: Mapping[str, ServiceProcess], out: Callable[[str], None], restart: bool = False,
                 max_restarts: int = 3, expected: tuple[str, ...] = HUMAN_SOURCES, fatal: bool = False) -> None:
        self.procs = procs
        self.out = out
        self.restart = restart
        self.max_restarts = max_restarts
        self.expected = expected
        self.fatal = fatal
        self.fatal_fault: str | None = None
        self.faults: list[tuple[str, int | None]] = []
        self.restarts: dict[str, int] = {}
        self._reported: set[str] = set()

    def check(self, skip: tuple[str, ...] = ("executor",)) -> None:
        """Look at every process once (the ``skip`` ones are the caller's to watch)."""
        for name, proc in self.procs.items():
            if name in skip or proc.proc is None or proc.running or name in self._reported:
                continue
            code = proc.returncode
            if code == 0 and name in self.expected:
                self._reported.add(name)
                continue
            self.faults.append((name, code))
            done = self.restarts.get(name, 0)
            if self.restart and done < self.max_restarts:
                self.restarts[name] = done + 1
                self.out(f"foresight demo: {name} {describe_exit(code)}: {proc.tail(1) or '(no output)'}; "
                         f"restarting it ({done + 1} of {self.max_restarts}); the executor holds until its "
                         "outputs are fresh")
                proc.start()
                continue
            self._reported.add(name)
            if self.fatal:
                self.fatal_fault = self.fatal_fault or name
                self.out(f"foresight demo: {name} {describe_exit(code)}: {proc.tail(1) or '(no output)'}; a lock-step "
                         "run cannot go on without it (every tick waits for it): stopping the run (--restart starts "
                         "a dead service again)")
                continue
            self.out(f"foresight demo: {name} {describe_exit(code)}: {proc.tail(1) or '(no output)'}; carrying on "
                     "without it (the executor holds while its outputs are missing)")
