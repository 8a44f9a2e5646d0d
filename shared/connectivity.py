"""Whether a session reaches its router or peers: said within seconds, retried with a bounded back-off.

Zenoh opens a peer session at once even when none of its ``connect`` endpoints answers, and keeps
trying them in the background (every :data:`RETRY_FIRST_MS` ms at first, growing to
:data:`RETRY_MAX_MS`: set explicitly by :func:`retry_config`); a client session is retried by
:func:`shared.transport.open_with_retry`. Either way, a service with a wrong endpoint used to run
without a word. :class:`ConnectionWatch` (started by :func:`shared.transport.open_session` for every
session with ``connect`` endpoints) polls the session's routers and peers and logs:

* ``no router or peer at tcp/127.0.0.1:1 after 3 s; Zenoh retries every 1-4 s; next report in 6 s``,
  then again after 6, 12, 24, 48, 60, 60, ... s while nothing answers (a bounded back-off of the reports);
* ``connected to tcp/127.0.0.1:7447 after 7.2 s`` once something answers (only after a warning);
* ``lost every router and peer (tcp/127.0.0.1:7447)`` when all connections drop, then the same reports;
* with ``ZenohConfig.require_connection`` the session's ``with`` body starts only once something answers; with
  nothing reached within ``connect_timeout_s`` it sets the service's stop event, and the ``with`` raises
  :class:`shared.transport.TransportError` ``gave up: no router or peer at ... within N s`` (the service exits with
  that one line, status 2) without having begun its work (before, a service waited for its peers and wrote a log
  file meanwhile: a review's executor wrote a 5-message MCAP, then gave up).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import zenoh

from shared.config import ZenohConfig

__all__ = ["RETRY_FIRST_MS", "RETRY_MAX_MS", "FIRST_REPORT_S", "MAX_REPORT_S", "retry_config", "ConnectionWatch",
           "watched"]

log = logging.getLogger("foresight.connectivity")

RETRY_FIRST_MS = 1000
"""Zenoh's first pause before retrying an unreachable ``connect`` endpoint (ms); doubles up to :data:`RETRY_MAX_MS`."""
RETRY_MAX_MS = 4000
FIRST_REPORT_S = 3.0
"""Seconds without a router or peer before the first warning; the next ones follow after 2x, 4x, ... that."""
MAX_REPORT_S = 60.0
"""Longest pause between two warnings while nothing answers."""
POLL_S = 0.25


def retry_config() -> dict[str, object]:
    """Zenoh's ``connect/retry`` settings (every mode), as :func:`shared.transport.zenoh_config` sets them."""
    return {"period_init_ms": RETRY_FIRST_MS, "period_max_ms": RETRY_MAX_MS, "period_increase_factor": 2}


def tls_hint(cfg: ZenohConfig) -> str:
    """Why a link does not come up under mutual TLS (appended to the warnings), or ``""``.

    Without security: whether the first ``connect`` endpoint is a secure router's (it answers a TLS handshake).

    One handshake with the first ``connect`` endpoint (:func:`shared.security.probe.diagnose`) says which: nothing
    listening, the router's certificate from another authority or for other names, this machine's refused.
    """
    if not cfg.security_dir:  # a plain session at a secure router's port: say so rather than "not reachable"
        from shared.security.probe import speaks_tls

        first = cfg.connect[0] if cfg.connect else ""
        if first.startswith("tcp/") and speaks_tls(first):
            return (f" ({first.removeprefix('tcp/')} speaks TLS: a secure router; give --security DIR and this "
                    "service's --role)")
        return ""
    from shared.security.probe import diagnose

    role = cfg.role or "observer"
    endpoints = connect_names(cfg).split(",")
    what = diagnose(endpoints[0], cfg.security_dir, role) if endpoints[0] else "no endpoint to connect to"
    return f" (mutual TLS as {role}: {what}; `foresight security check DIR`)"


def connect_names(cfg: ZenohConfig) -> str:
    """The session's ``connect`` endpoints as it uses them, comma-separated.

    Under security that is ``tls/``: the config's ``tcp/`` is what the user wrote, and the warnings named it though
    every link was TLS.
    """
    if not cfg.security_dir:
        return ",".join(cfg.connect)
    from shared.security.tls import secure_endpoints

    try:
        return ",".join(secure_endpoints(cfg.connect))
    except ValueError:  # an endpoint security refuses: opening the session says so
        return ",".join(cfg.connect)


class ConnectionWatch:
    """A thread that reports a session without router or peer (see the module docstring).

    Args:
        connected: Returns whether the session reaches a router or a peer now (e.g. :meth:`reaches`).
        cfg: The session's options (``connect`` endpoints, ``require_connection``, ``connect_timeout_s``).
        name: Who reports (the service's name).
        stop: Set when the session gives up (``require_connection``); None: never give up.
        clock: Monotonic clock (seconds).
    """

    def __init__(self, connected: Callable[[], bool], cfg: ZenohConfig, name: str = "zenoh",
                 stop: threading.Event | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self._connected = connected
        self.cfg = cfg
        self.name = name
        self.stop = stop
        self.clock = clock
        self.failed: str | None = None
        self.warnings = 0
        self._where = connect_names(cfg)
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self._since = clock()  # start of the current spell without a connection
        self._up = False
        self._ever_up = False
        self._next_report = FIRST_REPORT_S  # seconds into the spell of the next warning
        self._interval = FIRST_REPORT_S

    @staticmethod
    def reaches(session: zenoh.Session) -> bool:
        """Whether ``session`` is connected to at least one router or peer."""
        info = session.info
        return bool(list(info.routers_zid())) or bool(list(info.peers_zid()))

    def start(self) -> ConnectionWatch:
        """Start polling in a daemon thread (returns self)."""
        self._thread = threading.Thread(target=self._loop, name=f"{self.name}-connection-watch", daemon=True)
        self._thread.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        """Stop polling (before the session closes)."""
        self._done.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def wait_connected(self, stop: threading.Event | None = None) -> None:
        """Block until the session has reached a router or peer, the watch gave up, or ``stop`` (or :meth:`close`)."""
        while not (self._ever_up or self.failed is not None or self._done.is_set()
                   or (stop is not None and stop.is_set())):
            time.sleep(POLL_S / 4)

    def _loop(self) -> None:
        while not self._done.wait(POLL_S):
            try:
                up = self._connected()
            except Exception:  # the session is closing
                return
            self.poll(up)

    def poll(self, up: bool) -> None:
        """One observation: the session reaches something (``up``) or not; logs what changed."""
        now = self.clock()
        if up:
            if not self._up and self.warnings:
                log.info("%s: connected to %s after %.1f s", self.name, self._where, now - self._since)
            self._up = self._ever_up = True
            return
        if self._up:  # every connection dropped
            self._up = False
            self._since, self._next_report, self._interval = now, FIRST_REPORT_S, FIRST_REPORT_S
            self.warnings += 1
            log.warning("%s: lost every router and peer (%s); Zenoh retries every %g-%g s", self.name, self._where,
                        RETRY_FIRST_MS / 1000, RETRY_MAX_MS / 1000)
            return
        waited = now - self._since
        limit = self.cfg.connect_timeout_s
        if self.cfg.require_connection and not self._ever_up and waited >= limit and self.failed is None:
            self.failed = (f"{self.name}: gave up: no router or peer at {self._where} within {limit:g} s "
                           "(zenoh.require_connection)")  # said once, by the TransportError the session raises
            if self.stop is not None:
                self.stop.set()
            return
        if waited >= self._next_report:
            self.warnings += 1
            what = "no router or peer" if not self._ever_up else "still no router or peer"
            hint = tls_hint(self.cfg)
            log.warning("%s: %s at %s after %.0f s; Zenoh retries every %g-%g s; next report in %.0f s%s",
                        self.name, what, self._where, waited, RETRY_FIRST_MS / 1000, RETRY_MAX_MS / 1000,
                        self._interval, hint)
            self._next_report += self._interval
            self._interval = min(2 * self._interval, MAX_REPORT_S)


@contextmanager
def watched(session: zenoh.Session, cfg: ZenohConfig, name: str, stop: threading.Event | None) -> Iterator[None]:
    """Watch ``session`` (with ``connect`` endpoints, not a router) while the ``with`` body runs.

    Raises:
        TransportError: On exit, if the watch gave up (``require_connection``): its one line.
    """
    if not cfg.connect or cfg.mode == "router":
        yield
        return
    from shared.transport import TransportError

    watch = ConnectionWatch(lambda: ConnectionWatch.reaches(session), cfg, name, stop).start()
    if cfg.require_connection:  # the body (a service's work: its log file, its waits for peers) only once connected
        watch.wait_connected(stop)
        if watch.failed is not None:
            watch.close()
            raise TransportError(watch.failed)
    try:
        yield
    finally:
        watch.close()
    if watch.failed is not None:
        raise TransportError(watch.failed)
