"""Which services are up: each service's liveliness token, its peers' tokens, and a peer's departure.

A service declares ``<prefix>/alive/<service>`` and watches every token of the run. A peer named in
``stop_with`` (the executor, for a compose stack's planner, predictor and tracker) ends the service once it has
come and gone. A token also disappears when *this* session loses its connection: Zenoh reports every remote
token deleted when the router goes, and the router's restart (compose restarts it) used to stop every such
service for good while the executor reconnected and held the robot (a review script: the router down for 6 s;
planner, predictor and tracker stopped, the executor held for the rest of the run). A deletion that comes with the
link down, or with the link found gone within :data:`LINK_WINDOW_S` of it (the router's deletions and the link's
end come together: the link was already down at 3 of 3 deletions measured, still up at 1 of 3 in a test), is the
link's: the peer has :data:`REJOIN_S` from the link's return to come back, and a link that stays lost ends the wait
after :data:`CUT_WAIT_S`. A deletion with the link up is the peer's own (it withdrew its token as it ended): it
counts after :data:`DEPARTURE_GRACE_S` unless the token comes back, even if the link goes later (in peer mode the
departed peer may have been the link, as in the README's one-service block).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

import zenoh

from shared.protocol import Keys
from shared.rejects import escaped
from shared.security.guard import denied

__all__ = ["Presence", "DEPARTURE_GRACE_S", "REJOIN_S", "CUT_WAIT_S", "UNSEEN_WARN_S", "WAIT_REPORT_S", "connected"]

log = logging.getLogger("shared.transport")

DEPARTURE_GRACE_S = 1.0
"""A ``stop_with`` peer's token gone this long, this session linked all the while, is a departure."""

REJOIN_S = 10.0
"""After this session's link comes back, how long a vanished ``stop_with`` peer has to come back too: it reconnects on
its own, Zenoh retrying every 1-4 s (a peer reconnecting 1-4 s after this session was taken for gone)."""

CUT_WAIT_S = 30.0
"""Without any link, how long a peer lost with it is waited for before its departure counts (a router restart, as
compose does it, takes seconds)."""

POLL_S = 0.1
"""How often a vanished peer's token and this session's link are looked at."""

UNSEEN_WARN_S = 60.0
"""A ``stop_with`` peer not seen this long after the start is said, once."""

WAIT_REPORT_S = 10.0
"""Period of the "still waiting" lines of :meth:`Presence.wait_for` (a first start compiling torch takes a minute)."""

LINK_WINDOW_S = 0.5
"""A link found gone this soon after a peer's token is taken to have gone first (the router's loss: the deletions
and the link's end come together, in either order); later, the peer left and its link went with it (peer mode)."""


def connected(session: zenoh.Session) -> bool:
    """Whether ``session`` is linked to any router or peer."""
    info = session.info
    return any(True for _ in info.routers_zid()) or any(True for _ in info.peers_zid())


class Presence:
    """Declares this service's liveliness token and logs when peer services appear or disappear.

    Args:
        session: Open Zenoh session.
        keys: The run's key expressions.
        service: This service's name (its token is ``<prefix>/alive/<service>``).
        on_change: Called with ``(peer, appeared)`` on every change.
        stop_with: Peers whose departure ends this service: once one of them has been seen and its
            token stays away (it finished, or its process ended), ``stop`` is set; a token lost with this
            session's own connection is not a departure (module docstring).
        stop: The service's stop event (needed with ``stop_with``).
        is_connected: Whether the session has a link (default :func:`connected`; tests replace it).
    """

    def __init__(self, session: zenoh.Session, keys: Keys, service: str,
                 on_change: Callable[[str, bool], None] | None = None, stop_with: Sequence[str] = (),
                 stop: threading.Event | None = None,
                 is_connected: Callable[[], bool] | None = None) -> None:
        if stop_with and stop is None:
            raise ValueError("Presence: stop_with needs the stop event")
        self.service = service
        self.alive: set[str] = set()
        self._seen: set[str] = set()
        self._stop_with = frozenset(stop_with)
        self._stop = stop
        self._lock = threading.Lock()
        self._on_change = on_change
        self._is_connected = is_connected or (lambda: connected(session))
        self._closed = threading.Event()
        self._generation: dict[str, int] = {}  # per peer: deletions seen (the newest deletion's watch counts)
        refused = denied(session, keys.alive(service), "token")
        if refused:
            log.warning("access control: %s", refused)
        self._token = session.liveliness().declare_token(keys.alive(service))
        self._sub = session.liveliness().declare_subscriber(keys.alive_all, self._handle, history=True)
        if self._stop_with:
            log.info("%s: will stop when %s has come and gone", service, ", ".join(sorted(self._stop_with)))
            threading.Thread(target=self._say_if_unseen, name="presence-unseen", daemon=True).start()

    def _say_if_unseen(self) -> None:
        """Say once when no ``stop_with`` peer has come within :data:`UNSEEN_WARN_S`: it does not end by itself.

        A service started after the executor had ended (the tracker is in no default wait list) waited for it in
        silence, for ever (a review script: killed by its 45 s timeout, one log line).
        """
        if self._closed.wait(UNSEEN_WARN_S) or self._stop is None or self._stop.is_set():
            return
        with self._lock:
            seen = bool(self._seen)
        if not seen:
            log.warning("%s: %s not seen in %.0f s: this service ends when one of them has come and gone, or when "
                        "stopped", self.service, ", ".join(sorted(self._stop_with)), UNSEEN_WARN_S)

    def _handle(self, sample: zenoh.Sample) -> None:
        peer = str(sample.key_expr).rsplit("/", 1)[-1]
        up = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            (self.alive.add if up else self.alive.discard)(peer)
            ended = not up and peer in self._seen
            if up and peer in self._stop_with:
                self._seen.add(peer)
        if peer != self.service:  # escaped: any peer may declare a token whose name forges a log line of its own
            log.info("%s: peer %s %s", self.service, escaped(peer[:200]), "appeared" if up else "disappeared")
        if self._on_change is not None:
            try:
                self._on_change(peer, up)
            except Exception:  # the service's reaction failed: the departure below must still be acted on
                log.exception("%s: reacting to peer %s %s failed", self.service, escaped(peer[:200]),
                              "appearing" if up else "leaving")
        if ended and self._stop is not None:
            # lost with the link (the router went: the link is already down when the deletions come), or withdrawn
            # (the peer ended; a link lost after that, the peer's own in peer mode, changes nothing)
            with_link = not self._is_connected()
            with self._lock:  # this deletion's watch; an earlier one of the same peer ends at its next look
                generation = self._generation[peer] = self._generation.get(peer, 0) + 1
            threading.Thread(target=self._watch, args=(peer, generation, with_link), name=f"presence-{peer}",
                             daemon=True).start()

    def _watch(self, peer: str, generation: int, with_link: bool) -> None:
        """Set ``stop`` once ``peer`` stays away (module docstring), unless it comes back or the service ends."""
        deleted = time.monotonic()
        due = deleted + (REJOIN_S if with_link else DEPARTURE_GRACE_S)
        cut = None  # when this session's link was seen gone (None: linked)
        while not self._closed.is_set() and self._stop is not None and not self._stop.is_set():
            with self._lock:
                if self._generation.get(peer) != generation or peer in self.alive:
                    return
            now = time.monotonic()
            linked = self._is_connected()
            if not linked and not with_link and now - deleted <= LINK_WINDOW_S:
                with_link, due = True, deleted + REJOIN_S  # the link went with the token: the router's doing
            if with_link and not linked:
                if cut is None:
                    cut = now
                    log.warning("%s: no connection: %s's token went with it; waiting for the link (at most %.0f "
                                "s) before taking it as gone", self.service, peer, CUT_WAIT_S)
                if now - cut >= CUT_WAIT_S:
                    log.warning("%s: no connection for %.0f s and %s not back: taking it as gone", self.service,
                                CUT_WAIT_S, peer)
                    self._stop.set()
                    return
            else:
                if cut is not None:  # linked again: the peer reconnects on its own, give it the time to
                    log.info("%s: connected again; waiting up to %.0f s for %s", self.service, REJOIN_S, peer)
                    cut, due = None, now + REJOIN_S
                if now >= due:
                    log.info("%s: %s has gone: stopping", self.service, peer)
                    self._stop.set()
                    return
            self._closed.wait(POLL_S)

    def is_alive(self, service: str) -> bool:
        """Whether ``service``'s token is currently seen."""
        with self._lock:
            return service in self.alive

    def wait_for(self, services: Sequence[str], timeout: float, stop: threading.Event | None = None) -> list[str]:
        """Wait until every one of ``services`` is alive, at most ``timeout`` seconds (or until ``stop``).

        How a run waits for its peers before it starts (the executor before its first tick, a real-time
        replayer before streaming); what it waits for is logged when the wait starts, every
        :data:`WAIT_REPORT_S` while it lasts (a minute's silence read as a hang), and both outcomes.

        Returns:
            The services still missing (empty when all are present).
        """
        wanted = list(services)
        if not wanted:
            return []
        stop = stop or threading.Event()
        start = time.monotonic()
        deadline, report = start + timeout, start + WAIT_REPORT_S
        missing = [s for s in wanted if not self.is_alive(s)]
        if missing:
            log.info("%s: waiting for %s (at most %.0f s)", self.service, ", ".join(missing), timeout)
        while True:
            missing = [s for s in wanted if not self.is_alive(s)]
            if not missing:
                log.info("%s: %s present, starting", self.service, ", ".join(wanted))
                return []
            if stop.is_set():
                return missing
            now = time.monotonic()
            if now >= report and now < deadline:  # a long wait is said as it goes, not only at its end
                log.info("%s: still waiting for %s (%.0f s of at most %.0f s)", self.service, ", ".join(missing),
                         now - start, timeout)
                report += WAIT_REPORT_S
            if now >= deadline:
                log.warning("%s: starting without %s (not seen within %.1f s)", self.service, ", ".join(missing),
                            timeout)
                return missing
            stop.wait(0.02)

    def close(self) -> None:
        """Undeclare the token and the subscriber."""
        self._closed.set()
        self._sub.undeclare()
        self._token.undeclare()
