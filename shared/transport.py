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
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any, Generic, TypeVar

import zenoh

from shared.config import ZenohConfig
from shared.connectivity import connect_names, retry_config, tls_hint, watched
from shared.presence import Presence
from shared.protocol import Keys, Message, ProtocolError, Receipt, decode, encode
from shared.protocol.limits import MAX_PAYLOAD_BYTES
from shared.rejects import RejectCounter
from shared.security import OBSERVER
from shared.security.guard import denied, forget, remember
from shared.security.tls import listen_warning, security_settings
from shared.stopping import StoppedWhileStarting

__all__ = ["TransportError", "StoppedWhileConnecting", "MAX_MESSAGE_BYTES", "zenoh_config", "open_session",
           "open_with_retry", "TypedPublisher", "subscribe", "subscribe_ordered", "LatestSubscriber", "RejectCounter",
           "sender_of", "Presence", "describe"]

log = logging.getLogger(__name__)
M = TypeVar("M", bound=Message)


MAX_MESSAGE_BYTES = MAX_PAYLOAD_BYTES + 2 ** 20
"""Largest message a session receives: a payload at the wire's limit plus room for its key and attachment."""


def zenoh_config(cfg: ZenohConfig) -> zenoh.Config:
    """Build a ``zenoh.Config`` from a :class:`ZenohConfig` (explicit endpoints, scouting as set)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(cfg.mode))
    listen, connect, secure = security_settings(cfg)  # mutual TLS and access control, or nothing
    for path, value in secure.items():
        conf.insert_json5(path, json.dumps(value))
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("connect/endpoints", json.dumps(connect))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(bool(cfg.multicast_scouting)))
    conf.insert_json5("connect/retry", json.dumps(retry_config()))  # unreachable endpoints: retried 1, 2, 4, 4 ... s
    # Shared memory leaves segments in /dev/shm; our large messages are compact, so TCP on loopback is
    # enough (measured ~2.5 ms for 1 MB).
    conf.insert_json5("transport/shared_memory/enabled", "false")
    # a larger message is dropped by the link, which stays up (Zenoh's default took 1 GiB before decode refused it)
    conf.insert_json5("transport/link/rx/max_message_size", json.dumps(MAX_MESSAGE_BYTES))
    return conf


class TransportError(ValueError):
    """A Zenoh session could not be opened (e.g. the listen port is taken); the message says where."""


class StoppedWhileConnecting(TransportError, StoppedWhileStarting):
    """A client was stopped (SIGTERM, ``docker compose down``) while it still waited for its router: no error."""


RETRY_FIRST_S = 0.25
"""First pause before a client retries to reach its router; it doubles up to :data:`RETRY_MAX_S`."""
RETRY_MAX_S = 4.0


def _open(cfg: ZenohConfig) -> zenoh.Session:
    try:
        return zenoh.open(zenoh_config(cfg))
    except zenoh.ZError as exc:
        reason = str(exc).split(" at /")[0].strip()  # drop the Rust source location
        raise TransportError(f"zenoh: cannot open a {cfg.mode} session (listen {','.join(cfg.listen) or '-'}, "
                             f"connect {connect_names(cfg) or '-'}): {reason}") from None


def open_with_retry(cfg: ZenohConfig, sleep: Callable[[float], None] | None = None,
                    stop: threading.Event | None = None) -> zenoh.Session:
    """Open a Zenoh session; a client whose router is not there yet retries with a bounded back-off.

    Zenoh refuses to open a client session when none of its ``connect`` endpoints answers (a router
    that starts after the service). A client retries every 0.25, 0.5, 1, 2, 4, 4, ... s, logging
    each attempt, for at most ``cfg.connect_timeout_s``. A peer opens at once (Zenoh keeps trying
    its ``connect`` endpoints in the background); it logs a warning when none of them answered yet.
    ``stop`` (SIGTERM) ends the retries at once.

    Raises:
        TransportError: If the session cannot be opened (one line: mode, endpoints, Zenoh's reason;
            for a client: after the retries); :class:`StoppedWhileConnecting` when ``stop`` is set meanwhile.
    """
    stop = stop or threading.Event()
    sleep = sleep or stop.wait
    deadline = time.monotonic() + cfg.connect_timeout_s
    delay, attempt = RETRY_FIRST_S, 1
    while True:
        try:
            session = _open(cfg)
            break
        except TransportError as exc:
            left = deadline - time.monotonic()
            if cfg.mode != "client" or not cfg.connect or left <= 0 or stop.is_set():
                if attempt > 1 and stop.is_set():
                    raise StoppedWhileConnecting(f"stopped while waiting for the router {connect_names(cfg)}") from None
                if attempt > 1:
                    raise TransportError(f"{exc} (gave up after {attempt} attempts in {cfg.connect_timeout_s:g} s)"
                                         f"{tls_hint(cfg)}") from None
                raise
            pause = min(delay, left)
            log.warning("zenoh: router %s not reachable yet (attempt %d); retrying in %.2g s, at most %g s in all%s",
                        connect_names(cfg), attempt, pause, cfg.connect_timeout_s, tls_hint(cfg))
            sleep(pause)
            delay, attempt = min(2 * delay, RETRY_MAX_S), attempt + 1
    if attempt > 1:
        log.info("zenoh: connected to %s after %d attempts", connect_names(cfg), attempt)
    if cfg.mode == "peer" and cfg.connect:
        info = session.info
        if not list(info.routers_zid()) and not list(info.peers_zid()):
            log.warning("zenoh: %s not reachable yet; Zenoh keeps trying in the background (peer mode)",
                        connect_names(cfg))
    return session


@contextmanager
def open_session(cfg: ZenohConfig, stop: threading.Event | None = None, name: str = "zenoh") -> Iterator[zenoh.Session]:
    """Open a Zenoh session for ``cfg`` (see :func:`open_with_retry`), watch it, close it on exit.

    While open, :class:`shared.connectivity.ConnectionWatch` logs (as ``name``) when no router or peer
    answers; with ``cfg.require_connection`` it gives up by setting ``stop``.

    Raises:
        TransportError: If Zenoh refuses to open the session, or (on exit) the watch gave up (one line).
    """
    warning = listen_warning(cfg)  # beyond loopback without security, or on a host the certificate does not name
    if warning:  # once per session, not once per connection attempt of a retrying client
        log.warning("%s", warning)
    session = open_with_retry(cfg, stop=stop)
    if cfg.security_dir:
        remember(session, cfg.role or OBSERVER, Keys(cfg.prefix))
    try:
        with watched(session, cfg, name, stop):
            yield session
    finally:
        forget(session)
        session.close()


def sender_of(sample: zenoh.Sample) -> str:
    """Who published a sample: the session id :class:`TypedPublisher` attaches ("" when none)."""
    att = sample.attachment
    return att.to_bytes()[:64].decode("ascii", "replace") if att is not None else ""


class TypedPublisher(Generic[M]):
    """Publisher of one message type on one key; encodes (and so validates) before sending.

    Every sample carries the publishing session's id as its Zenoh attachment (see :func:`sender_of`),
    so receivers check ticks and sequence numbers per sender (:class:`shared.protocol.Receipt`).
    """

    def __init__(self, session: zenoh.Session, key: str, block: bool = False) -> None:
        """Declare the publisher.

        Args:
            session: Open Zenoh session.
            key: Key expression.
            block: Block ``put`` when the network is congested instead of dropping the message
                (Zenoh's default is to drop); use it for streams where every message counts.
        """
        self.key = key
        self.sender = str(session.zid())
        refused = denied(session, key, "put")
        if refused:
            log.warning("access control: %s", refused)
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self._pub = session.declare_publisher(key, congestion_control=cc)

    def put(self, msg: M) -> bytes:
        """Encode and publish ``msg``; returns the bytes sent (for logging)."""
        data = encode(msg)
        self._pub.put(data, attachment=self.sender.encode())
        return data

    def matched(self) -> bool:
        """Whether a subscriber (in any session Zenoh routes to) matches the key now."""
        return bool(self._pub.matching_status.matching)

    def undeclare(self) -> None:
        """Release the publisher."""
        self._pub.undeclare()


def subscribe(session: zenoh.Session, key: str, cls: type[M], callback: Callable[[M], None],
              rejects: RejectCounter | None = None, receipt: Receipt | None = None) -> zenoh.Subscriber:
    """Subscribe to ``key``, decode each payload as ``cls`` and call ``callback`` with it.

    Malformed payloads (and, with ``receipt``, messages whose values or order it refuses) are
    counted and logged by ``rejects`` and never reach ``callback``; an exception raised by
    ``callback`` itself is counted there too (reason ``handler``, its traceback once per key) and does not stop
    the subscription.

    Args:
        session: Open Zenoh session.
        key: Key expression (one key, no wildcard).
        cls: Expected message type.
        callback: Called on Zenoh's thread with each valid message.
        rejects: Where to count rejections (default: a counter of the subscription's own).
        receipt: The receiving service's checks (values against its expectations, per-sender
            order); default: decoding only.
    """
    return subscribe_ordered(session, key, {key: cls}, callback, rejects, receipt)  # type: ignore[arg-type]


def subscribe_ordered(session: zenoh.Session, key_expr: str, types: Mapping[str, type[Message]],
                      callback: Callable[[Message], None], rejects: RejectCounter | None = None,
                      receipt: Receipt | None = None) -> zenoh.Subscriber:
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
        rejects: Where to count rejections (default: a counter of this subscription's own).
        receipt: As in :func:`subscribe`.
    """
    default_rejects = RejectCounter("subscriber")

    def handler(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            cls = types.get(key)
            if cls is None:  # counted under the expression: a flood of new keys is one counter, rate-limited
                (rejects or default_rejects).reject(key_expr, ProtocolError(f"message: unexpected key {key}",
                                                                            "wrong-type"))
                return
            payload = sample.payload.to_bytes()
            msg = (receipt.accept(key, payload, cls, sender_of(sample)) if receipt is not None
                   else decode(payload, cls))
        except ProtocolError as exc:
            (rejects or default_rejects).reject(key, exc)  # counted, one log line per key per second
            return
        except Exception as exc:  # a decoder bug: refused all the same, its traceback once
            (rejects or default_rejects).unexpected(key, exc, "decoding a message")
            return
        try:
            callback(msg)
        except Exception as exc:  # a bug in one handler must not kill the subscription: its traceback once, counted
            (rejects or default_rejects).unexpected(key, exc, "handling a message")

    for key in dict.fromkeys((key_expr, *types)):  # the expression itself too: one refused is refused whole
        refused = denied(session, key, "subscribe")
        if refused:
            log.warning("access control: %s", refused)
    return session.declare_subscriber(key_expr, handler)


class LatestSubscriber(Generic[M]):
    """Keeps only the newest valid message of a key (for large messages such as occupancy grids).

    A slow consumer calls :meth:`take` and gets the latest message; older ones are dropped, never
    queued. Decoding happens on Zenoh's thread so a malformed newer payload never hides a good one.
    """

    def __init__(self, session: zenoh.Session, key: str, cls: type[M],
                 rejects: RejectCounter | None = None,
                 on_message: Callable[[M], None] | None = None, receipt: Receipt | None = None) -> None:
        self._cond = threading.Condition()
        self._latest: M | None = None
        self._seq = 0
        self._taken = 0
        self._on_message = on_message
        self._sub = subscribe(session, key, cls, self._store, rejects, receipt)

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


def describe(session: zenoh.Session) -> dict[str, Any]:
    """Session id and peers/routers it is connected to (for logs)."""
    info = session.info
    return {"zid": str(session.zid()), "peers": [str(z) for z in info.peers_zid()],
            "routers": [str(z) for z in info.routers_zid()]}
