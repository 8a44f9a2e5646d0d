"""A minimal client of Foxglove's WebSocket protocol: connect, subscribe to channels, receive messages.

What the Foxglove app does when it opens ``ws://HOST:PORT``, reduced to what checks need: the tests and
``foresight bench live`` use it to watch a :class:`~shared.foxglove.live.LiveServer` without the app.
The protocol (subprotocol ``foxglove.sdk.v1``): the server sends JSON ``serverInfo`` and ``advertise``
(``channels``: id, topic, encoding, schemaName, schema, schemaEncoding); the client sends ``subscribe``
(``subscriptions``: its own id per channel id); the server sends each message as a binary frame: opcode
``0x01``, the subscription id (uint32 LE), the log time (uint64 LE, ns), the payload.
"""

from __future__ import annotations

import json
import struct
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

__all__ = ["FoxgloveClient", "Received", "SUBPROTOCOL"]

SUBPROTOCOL = "foxglove.sdk.v1"
_MESSAGE_DATA = 0x01


@dataclass
class Received:
    """One message received on a subscribed channel."""

    topic: str
    log_time: int
    data: bytes
    received_ns: int = field(default_factory=time.time_ns)


class FoxgloveClient:
    """Connects to a Foxglove WebSocket server and subscribes to its channels; a context manager.

    Args:
        url: ``ws://HOST:PORT``.
        timeout_s: How long :meth:`connect` keeps trying (the server may still be starting).
        keepalive: Ping the server every 20 s (websockets' default). A client that reads nothing stops reading the
            pongs too, and its own keepalive closed it after 40 s with a traceback: a stalled client (``foresight
            bench live --slow-client``) keeps its connection without.

    Attributes:
        server_info: The server's ``serverInfo`` message.
        channels: Advertised channels by id (each the ``advertise`` entry: topic, encoding, schemaName, ...).
    """

    def __init__(self, url: str, timeout_s: float = 10.0, keepalive: bool = True) -> None:
        self.url = url
        self.timeout_s = timeout_s
        self.keepalive = keepalive
        self.server_info: dict[str, Any] = {}
        self.channels: dict[int, dict[str, Any]] = {}
        self._subscriptions: dict[int, str] = {}
        self._ws: ClientConnection | None = None
        self._stack = ExitStack()

    def connect(self) -> FoxgloveClient:
        """Open the connection (retrying until ``timeout_s``) and read the server's info and first advertisement."""
        deadline = time.monotonic() + self.timeout_s
        while True:
            try:
                self._ws = self._stack.enter_context(
                    connect(self.url, subprotocols=[SUBPROTOCOL], open_timeout=2.0,  # type: ignore[list-item]
                            ping_interval=20.0 if self.keepalive else None))
                break
            except (OSError, TimeoutError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        while not (self.server_info and self.channels) and not self.closed and time.monotonic() < deadline:
            self._next(max(0.1, deadline - time.monotonic()))
        return self

    def subscribe(self, topics: list[str] | None = None) -> list[str]:
        """Subscribe to the advertised channels of ``topics`` (default: all); returns the topics subscribed."""
        chosen = [(cid, ch["topic"]) for cid, ch in self.channels.items() if topics is None or ch["topic"] in topics]
        subs = [{"id": cid, "channelId": cid} for cid, _ in chosen]  # one subscription id per channel: its id
        self._send({"op": "subscribe", "subscriptions": subs})
        self._subscriptions.update(dict(chosen))
        return [t for _, t in chosen]

    def receive(self, duration_s: float) -> list[Received]:
        """Every message received within ``duration_s``, or until the server closes the connection.

        Advertisements that come meanwhile are taken in (:attr:`channels`).
        """
        out: list[Received] = []
        end = time.monotonic() + duration_s
        while (left := end - time.monotonic()) > 0 and not self.closed:
            msg = self._next(left)
            if isinstance(msg, Received):
                out.append(msg)
        return out

    def _send(self, obj: dict[str, Any]) -> None:
        assert self._ws is not None, "connect() first"
        self._ws.send(json.dumps(obj))

    def _next(self, timeout: float) -> Received | dict[str, Any] | None:
        """One frame: a message (Received), a control message (dict), or None (timeout, or the server closed)."""
        assert self._ws is not None, "connect() first"
        try:
            frame = self._ws.recv(timeout=timeout)
        except (TimeoutError, ConnectionClosed):
            return None
        if isinstance(frame, str):
            obj = json.loads(frame)
            if obj.get("op") == "serverInfo":
                self.server_info = obj
            elif obj.get("op") == "advertise":
                self.channels.update({int(ch["id"]): ch for ch in obj["channels"]})
            elif obj.get("op") == "unadvertise":
                for cid in obj.get("channelIds", []):
                    self.channels.pop(int(cid), None)
            return obj
        if len(frame) >= 13 and frame[0] == _MESSAGE_DATA:
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            return Received(self._subscriptions.get(sub, str(sub)), log_time, bytes(frame[13:]))
        return None

    @property
    def closed(self) -> bool:
        """Whether the server closed the connection (or it was never opened)."""
        return self._ws is None or self._ws.protocol.state.name == "CLOSED"

    def close(self) -> None:
        """Close the connection; idempotent."""
        self._stack.close()

    def __enter__(self) -> FoxgloveClient:
        return self.connect()

    def __exit__(self, *exc: object) -> None:
        self.close()
