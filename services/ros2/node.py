"""A ROS 2 node on a Zenoh session as rmw_zenoh makes one: its graph tokens, publishers and subscriptions.

The format is :mod:`services.ros2.wire`'s; this is its use on a live session. A publisher numbers its
samples from 1 and attaches rmw_zenoh's 33 bytes (sequence number, source time, its GID: rmw_zenoh's, the hash of
its graph token, so that a subscriber gets the GID ``ros2 topic info -v`` shows); a subscription
listens on its topic and type with any type hash, so that a sample of another hash (another definition of
the type) is refused with its reason rather than never seen, and refuses a sample without rmw_zenoh's
attachment, as a ROS 2 subscription does. Refusals go to a :class:`shared.rejects.RejectCounter`: one
logged line each (rate-limited), counted by reason.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from typing import Any

from shared.rejects import RejectCounter

from .wire import (
    HUMBLE_TYPE_HASH,
    Attachment,
    AttachmentError,
    data_key,
    endpoint_gid,
    endpoint_token,
    node_token,
    qos_chunk,
)

__all__ = ["Ros2Node", "Ros2Publisher", "next_entity_id"]

_IDS: dict[str, itertools.count] = {}
_IDS_LOCK = threading.Lock()


def next_entity_id(zid: str) -> int:
    """The next id of a node or an entity (publisher, subscription) on the session ``zid``, from 0.

    Unique within the session, as rmw_zenoh numbers them from one counter per context: two nodes on one
    session have distinct graph tokens and their publishers distinct GIDs.
    """
    with _IDS_LOCK:
        return next(_IDS.setdefault(zid, itertools.count()))


class Ros2Publisher:
    """One topic's publisher: CDR payloads out with the attachment, numbered from 1."""

    def __init__(self, session: Any, key: str, gid: bytes) -> None:
        self.key = key
        self.gid = gid
        self.sent = 0
        self._lock = threading.Lock()
        self._pub = session.declare_publisher(key)

    def put(self, payload: bytes) -> None:
        """Publish one sample."""
        with self._lock:
            self.sent += 1
            attachment = Attachment(self.sent, time.time_ns(), self.gid).encode()
            self._pub.put(payload, attachment=attachment)

    def undeclare(self) -> None:
        """Stop publishing."""
        self._pub.undeclare()


class Ros2Node:
    """A node's graph presence on ``session``; publishers and subscriptions declared through it.

    Args:
        session: An open Zenoh session (connected to the ROS 2 side's router).
        domain_id: ROS 2 domain; ``namespace`` (absolute) and ``name``: the node's.
        hashes: RIHS01 hash per message type (:attr:`services.ros2.core.Ros2Mapping.hashes`).
        rejects: Where refused samples are counted (keyed by topic).
        ordered: Handle all subscriptions in one Zenoh subscriber, one sample at a time in arrival order (as a ROS 2
            node's single-threaded executor does), at the price of receiving every topic of the domain; else one
            Zenoh subscriber per topic, whose callbacks may run concurrently.
    """

    def __init__(self, session: Any, domain_id: int, namespace: str, name: str, hashes: dict[str, str],
                 rejects: RejectCounter, ordered: bool = False) -> None:
        self.session = session
        self.domain_id, self.namespace, self.name = domain_id, namespace, name
        self.hashes = hashes
        self.rejects = rejects
        self.zid = str(session.zid())
        self.node_id = next_entity_id(self.zid)
        self._tokens = [session.liveliness().declare_token(node_token(domain_id, self.zid, self.node_id, namespace,
                                                                      name))]
        self._undeclare: list[Any] = []
        self._handlers: dict[str, tuple[str, str, Callable[[bytes], None]]] = {}
        self._subscriber: Any = None
        self.ordered = ordered

    def _token(self, kind: str, topic: str, msgtype: str) -> bytes:
        """Declare the entity's graph token (its QoS written out in full); its GID."""
        entity = next_entity_id(self.zid)

        def token(explicit: bool) -> str:
            return endpoint_token(self.domain_id, self.zid, self.node_id, entity, kind, self.namespace, self.name,
                                  topic, msgtype, self.hashes[msgtype], qos_chunk(depth=10, explicit=explicit))

        self._tokens.append(self.session.liveliness().declare_token(token(True)))
        # rmw_zenoh hashes the token as it re-writes it (QoS defaults blank), not the string it received
        return endpoint_gid(token(False))

    def publisher(self, topic: str, msgtype: str) -> Ros2Publisher:
        """A publisher of ``msgtype`` on the absolute ``topic``, with its ``MP`` token and rmw_zenoh's GID for it."""
        gid = self._token("MP", topic, msgtype)
        pub = Ros2Publisher(self.session, data_key(self.domain_id, topic, msgtype, self.hashes[msgtype]), gid)
        self._undeclare.append(pub)
        return pub

    def subscription(self, topic: str, msgtype: str, callback: Callable[[bytes], None]) -> None:
        """Call ``callback(payload)`` per sample of ``msgtype`` on ``topic`` with the type's hash and an attachment.

        The subscription's ``MS`` token is declared; the callback may raise ``ValueError`` to refuse a sample (any
        other exception is counted as reason ``handler``, its traceback logged the first time on the topic; the node
        goes on).
        With ``ordered``, all of a node's subscriptions share one Zenoh subscriber (on the domain's keys), so that
        its callbacks run one at a time in the order the samples arrived (Zenoh calls each subscriber's callback on
        a thread of its own: a command and the ``/clock`` after it could otherwise be handled the other way round).
        """
        self._token("MS", topic, msgtype)
        prefix = data_key(self.domain_id, topic, msgtype, "")
        self._handlers[prefix] = (topic, msgtype, callback)
        if not self.ordered:
            self._undeclare.append(self.session.declare_subscriber(prefix + "*", self._on_sample))
        elif self._subscriber is None:
            self._subscriber = self.session.declare_subscriber(f"{self.domain_id}/**", self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        key = str(sample.key_expr)
        prefix, _, got = key.rpartition("/")
        handler = self._handlers.get(prefix + "/")
        if handler is None:
            return  # another topic of the domain
        topic, msgtype, callback = handler
        expected = self.hashes[msgtype]
        if got == HUMBLE_TYPE_HASH:
            self.rejects.reject(topic, f"{msgtype}: a ROS 2 Humble node (rmw_zenoh on Humble sends no type hash): "
                                "not supported, docs/ros2.md", reason="type")
            return
        if got != expected:
            self.rejects.reject(topic, f"{msgtype}: type hash {got}, expected {expected} (another definition)",
                                reason="type")
            return
        try:
            att = sample.attachment
            Attachment.decode(att.to_bytes() if att is not None else None)
        except AttachmentError as exc:
            self.rejects.reject(topic, exc, reason="attachment")
            return
        try:
            callback(sample.payload.to_bytes())
        except ValueError as exc:  # Ros2InputError: not the type's CDR, or values the receiver refuses
            self.rejects.reject(topic, exc)
        except Exception as exc:  # the receiver's fault, not the sample's: counted, its traceback once per topic
            self.rejects.unexpected(topic, exc, f"handling a {msgtype} sample")

    def close(self) -> None:
        """Undeclare the subscriptions, publishers and tokens."""
        if self._subscriber is not None:
            self._subscriber.undeclare()
        for item in reversed(self._undeclare):
            item.undeclare()
        for token in self._tokens:
            token.undeclare()
