"""Zenoh transport: a session factory and typed publish/subscribe helpers.

Defaults are loopback-only with multicast scouting off (see :class:`shared.config.ZenohConfig`).

Example:
    >>> with open_session(ZenohConfig()) as session:          # doctest: +SKIP
    ...     pub = TypedPublisher(session, Keys().pose)
    ...     pub.put(pose)
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import zenoh

from shared.config import ZenohConfig
from shared.protocol import Keys, Message, ProtocolError, decode, encode

__all__ = [
    "TransportError",
    "zenoh_config",
    "open_session",
    "TypedPublisher",
    "subscribe",
    "subscribe_ordered",
    "LatestSubscriber",
    "RejectCounter",
    "Presence",
    "describe",
]

log = logging.getLogger(__name__)
M = TypeVar("M", bound=Message)


def zenoh_config(cfg: ZenohConfig) -> zenoh.Config:
    """Build a ``zenoh.Config`` from a :class:`ZenohConfig` (explicit endpoints, scouting as set)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(cfg.mode))
    conf.insert_json5("listen/endpoints", json.dumps(list(cfg.listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(cfg.connect)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(bool(cfg.multicast_scouting)))
    # Shared memory leaves segments in /dev/shm; our large messages are compact, so TCP on loopback is
    # enough (measured ~2.5 ms for 1 MB).
    conf.insert_json5("transport/shared_memory/enabled", "false")
    return conf


class TransportError(ValueError):
    """A Zenoh session could not be opened (e.g. the listen port is taken); the message says where."""


@contextmanager
def open_session(cfg: ZenohConfig) -> Iterator[zenoh.Session]:
    """Open a Zenoh session for ``cfg`` and close it on exit.

    Raises:
        TransportError: If Zenoh refuses to open the session (one-line message with the endpoints).
    """
    try:
        session = zenoh.open(zenoh_config(cfg))
    except zenoh.ZError as exc:
        reason = str(exc).split(" at /")[0].strip()  # drop the Rust source location
        raise TransportError(f"zenoh: cannot open a {cfg.mode} session (listen {','.join(cfg.listen) or '-'}, "
                             f"connect {','.join(cfg.connect) or '-'}): {reason}") from None
    try:
        yield session
    finally:
        session.close()


class TypedPublisher(Generic[M]):
    """Publisher of one message type on one key; encodes (and so validates) before sending."""

    def __init__(self, session: zenoh.Session, key: str, block: bool = False) -> None:
        """Declare the publisher.

        Args:
            session: Open Zenoh session.
            key: Key expression.
            block: Block ``put`` when the network is congested instead of dropping the message
                (Zenoh's default is to drop); use it for streams where every message counts.
        """
        self.key = key
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self._pub = session.declare_publisher(key, congestion_control=cc)

    def put(self, msg: M) -> bytes:
        """Encode and publish ``msg``; returns the bytes sent (for logging)."""
        data = encode(msg)
        self._pub.put(data)
        return data

    def undeclare(self) -> None:
        """Release the publisher."""
        self._pub.undeclare()


@dataclass
class RejectCounter:
    """Counts and logs rejected messages per key, rate-limited to one log line per key per second."""

    service: str
    counts: dict[str, int] = field(default_factory=dict)
    _last_log: dict[str, float] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def reject(self, key: str, error: Exception) -> None:
        """Record one rejected message on ``key``."""
        import time

        with self._lock:
            self.counts[key] = self.counts.get(key, 0) + 1
            now = time.monotonic()
            if now - self._last_log.get(key, -1e9) >= 1.0:
                self._last_log[key] = now
                log.warning("%s: rejected message on %s (%d so far): %s", self.service, key,
                            self.counts[key], error)

    @property
    def total(self) -> int:
        """Total rejected messages."""
        with self._lock:
            return sum(self.counts.values())


def subscribe(session: zenoh.Session, key: str, cls: type[M], callback: Callable[[M], None],
              rejects: RejectCounter | None = None) -> zenoh.Subscriber:
    """Subscribe to ``key``, decode each payload as ``cls`` and call ``callback`` with it.

    Malformed payloads are counted and logged by ``rejects`` and never reach ``callback``; an
    exception raised by ``callback`` itself is logged and does not stop the subscription.

    Args:
        session: Open Zenoh session.
        key: Key expression (one key, no wildcard).
        cls: Expected message type.
        callback: Called on Zenoh's thread with each valid message.
        rejects: Where to count rejections (default: log only).
    """
    return subscribe_ordered(session, key, {key: cls}, callback, rejects)  # type: ignore[arg-type]


def subscribe_ordered(session: zenoh.Session, key_expr: str, types: Mapping[str, type[Message]],
                      callback: Callable[[Message], None], rejects: RejectCounter | None = None) -> zenoh.Subscriber:
    """One subscription over several keys that delivers their messages in publishing order.

    Zenoh runs each subscriber's callback on its own thread, so two :func:`subscribe` calls (e.g. on
    poses and on demonstration markers) may see messages of different keys out of order. This
    subscribes once to ``key_expr`` (a wildcard such as :attr:`Keys.human_all`) and decodes each
    sample as the type its key maps to in ``types``; samples on other keys are rejected.

    Args:
        session: Open Zenoh session.
        key_expr: Wildcard key expression covering the keys of ``types``.
        types: Key -> expected message type.
        callback: Called on one Zenoh thread with each valid message, in arrival order.
        rejects: Where to count rejections (default: log only).
    """

    def handler(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            cls = types.get(key)
            if cls is None:
                raise ProtocolError(f"message: unexpected key {key}")
            msg = decode(sample.payload.to_bytes(), cls)
        except ProtocolError as exc:
            if rejects is not None:
                rejects.reject(key, exc)
            else:
                log.warning("rejected message on %s: %s", key, exc)
            return
        try:
            callback(msg)
        except Exception:  # a bug in one handler must not kill the subscription
            log.exception("handler for %s failed", key)

    return session.declare_subscriber(key_expr, handler)


class LatestSubscriber(Generic[M]):
    """Keeps only the newest valid message of a key (for large messages such as occupancy grids).

    A slow consumer calls :meth:`take` and gets the latest message; older ones are dropped, never
    queued. Decoding happens on Zenoh's thread so a malformed newer payload never hides a good one.
    """

    def __init__(self, session: zenoh.Session, key: str, cls: type[M],
                 rejects: RejectCounter | None = None,
                 on_message: Callable[[M], None] | None = None) -> None:
        self._cond = threading.Condition()
        self._latest: M | None = None
        self._seq = 0
        self._taken = 0
        self._on_message = on_message
        self._sub = subscribe(session, key, cls, self._store, rejects)

    def _store(self, msg: M) -> None:
        with self._cond:
            self._latest = msg
            self._seq += 1
            self._cond.notify_all()
        if self._on_message is not None:
            self._on_message(msg)

    @property
    def latest(self) -> M | None:
        """The newest message received so far (or None), without consuming it."""
        with self._cond:
            return self._latest

    def take(self, timeout: float | None = None) -> M | None:
        """Wait up to ``timeout`` s for a message newer than the last one taken; return it or None."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._seq > self._taken, timeout=timeout):
                return None
            self._taken = self._seq
            return self._latest

    def wait_for(self, predicate: Callable[[M], bool], timeout: float) -> M | None:
        """Wait until the latest message satisfies ``predicate``; return it or None on timeout."""
        with self._cond:
            ok = self._cond.wait_for(lambda: self._latest is not None and predicate(self._latest),
                                     timeout=timeout)
            return self._latest if ok else None

    def undeclare(self) -> None:
        """Release the subscription."""
        self._sub.undeclare()


class Presence:
    """Declares this service's liveliness token and logs when peer services appear or disappear."""

    def __init__(self, session: zenoh.Session, keys: Keys, service: str,
                 on_change: Callable[[str, bool], None] | None = None) -> None:
        self.service = service
        self.alive: set[str] = set()
        self._lock = threading.Lock()
        self._on_change = on_change
        self._token = session.liveliness().declare_token(keys.alive(service))
        self._sub = session.liveliness().declare_subscriber(keys.alive_all, self._handle, history=True)

    def _handle(self, sample: zenoh.Sample) -> None:
        peer = str(sample.key_expr).rsplit("/", 1)[-1]
        up = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            (self.alive.add if up else self.alive.discard)(peer)
        if peer != self.service:
            log.info("%s: peer %s %s", self.service, peer, "appeared" if up else "disappeared")
        if self._on_change is not None:
            self._on_change(peer, up)

    def is_alive(self, service: str) -> bool:
        """Whether ``service``'s token is currently seen."""
        with self._lock:
            return service in self.alive

    def close(self) -> None:
        """Undeclare the token and the subscriber."""
        self._sub.undeclare()
        self._token.undeclare()


def describe(session: zenoh.Session) -> dict[str, Any]:
    """Session id and peers/routers it is connected to (for logs)."""
    info = session.info
    return {"zid": str(session.zid()), "peers": [str(z) for z in info.peers_zid()],
            "routers": [str(z) for z in info.routers_zid()]}
