"""Watching a run's service processes: a service that dies or hangs is reported once and the run carries on.

The executor holds the robot while the predictor, the planner or (mid-demonstration) the human's source is
gone (its ``hold_without``) or its inputs are stale, so one dead service is a fault to report, not a
reason to abort the run. With ``restart`` the supervisor starts it again (at most ``max_restarts``
times per service), and the executor resumes once the service's outputs are fresh. A lock-step run
(``fatal``) is different: every tick waits for every service's output, so without the dead service it
would crawl on at one timeout a tick; its death ends the run, its log complete.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping

from services.processes import ServiceProcess, describe_exit
from shared.presence import REJOIN_S
from shared.protocol import HUMAN_SOURCES
from shared.stopping import SHUTDOWN_GRACE_S

__all__ = ["Supervisor", "describe_exit", "HUNG_AFTER_S"]

log = logging.getLogger("foresight.supervisor")

HUNG_AFTER_S = REJOIN_S
"""Seconds a running service's liveliness token may stay gone before it counts as hung: as long as a peer whose link
dropped has to come back (:data:`shared.presence.REJOIN_S`; a link that drops takes 1-4 s to reconnect, and its
tokens are gone meanwhile). A stopped process's token goes when Zenoh's lease (10 s) drops its link."""


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
        is_alive: Whether a service's liveliness token is seen (:meth:`shared.transport.Presence.is_alive`): a
            running service whose token, once seen, stays gone ``hung_after_s`` is hung (SIGSTOP, a deadlock) and
            a fault as a death is (restarted: killed first). None: deaths only.
        hung_after_s: See ``is_alive`` (:data:`HUNG_AFTER_S`).
        clock: Seconds, monotonic.

    Attributes:
        faults: ``(service, exit status)`` of every death (status None: hung).
        fatal_fault: The service whose death (with ``fatal``) or hang (a ``skip`` one, the executor) ends the run
            (None while none did).
    """

    def __init__(self, procs: Mapping[str, ServiceProcess], out: Callable[[str], None], restart: bool = False,
                 max_restarts: int = 3, expected: tuple[str, ...] = HUMAN_SOURCES, fatal: bool = False,
                 is_alive: Callable[[str], bool] | None = None, hung_after_s: float = HUNG_AFTER_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.is_alive = is_alive
        self.hung_after_s = hung_after_s
        self.clock = clock
        self._seen: set[str] = set()
        self._gone_since: dict[str, float] = {}
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
        """Look at every process once.

        The ``skip`` ones' exit is the caller's to watch (the executor's ends the run); their hang is checked here and
        ends the run (:attr:`fatal_fault`), restart or not: a SIGSTOPped executor went unnoticed until ``--timeout``,
        15 silent minutes (a review). Their token may stay gone :data:`SHUTDOWN_GRACE_S` longer: the executor
        withdraws it at the run's end, then closes its log, which may take that long (a full disk's retries).
        """
        for name, proc in self.procs.items():
            if proc.proc is None or name in self._reported:
                continue
            if proc.running:
                if (gone_s := self._hung(name, SHUTDOWN_GRACE_S if name in skip else 0.0)) is None:
                    continue
                what = (f"{name} stopped answering (its process runs, but its liveliness token has been gone for "
                        f"{gone_s:.0f} s: hung or stopped)")
                if name not in skip:
                    self._fault(name, proc, None, what)
                    continue
                self.faults.append((name, None))
                self._reported.add(name)
                self.fatal_fault = self.fatal_fault or name
                self.out(f"foresight demo: {what}; the run cannot go on without it: stopping the run")
                continue
            if name in skip:
                continue
            code = proc.returncode
            if code == 0 and name in self.expected:
                self._reported.add(name)
                continue
            said = proc.last_words()  # a killed process's last line is not why it died: only an error's is
            self._fault(name, proc, code, f"{name} {describe_exit(code)}" + (f": {said}" if said else ""))

    def _hung(self, name: str, more_s: float = 0.0) -> float | None:
        """How long ``name``'s token, seen since it (re)started, has been gone, once ``hung_after_s + more_s``+."""
        if self.is_alive is None:
            return None
        if self.is_alive(name):
            self._seen.add(name)
            self._gone_since.pop(name, None)
            return None
        if name not in self._seen:  # starting, or started again: not up yet
            return None
        gone = self.clock() - self._gone_since.setdefault(name, self.clock())
        return gone if gone >= self.hung_after_s + more_s else None

    def _fault(self, name: str, proc: ServiceProcess, code: int | None, what: str) -> None:
        self.faults.append((name, code))
        self._seen.discard(name)
        self._gone_since.pop(name, None)
        done = self.restarts.get(name, 0)
        if self.restart and done < self.max_restarts:
            self.restarts[name] = done + 1
            self.out(f"foresight demo: {what}; restarting it ({done + 1} of {self.max_restarts}); the executor "
                     "holds until its outputs are fresh")
            proc.stop(timeout=2.0)  # a hung one is killed; a dead one has its status already
            proc.start()
            return
        self._reported.add(name)
        if self.fatal:
            self.fatal_fault = self.fatal_fault or name
            self.out(f"foresight demo: {what}; a lock-step run cannot go on without it (every tick waits for it): "
                     "stopping the run (--restart starts it again)")
            return
        self.out(f"foresight demo: {what}; carrying on without it (the executor holds while its outputs are "
                 "missing)")
