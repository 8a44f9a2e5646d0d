"""Foxglove's live WebSocket server (``foxglove-sdk``), one channel per scene topic.

Every channel of :data:`shared.foxglove.stream.SCHEMAS` is advertised from the start, so a client (the
Foxglove app, or any client of Foxglove's WebSocket protocol) can subscribe before the first message; a
message on a channel no client subscribes to costs nothing but the call (:meth:`LiveServer.watched` lets a caller
skip drawing it). The static scene (table, cups,
robot base) is sent again every ``static_period_s`` for apps that connect later (Foxglove keeps a scene
entity until it is replaced). The server has its own ``foxglove.Context``: nothing else logged through the
SDK in this process reaches it. A channel's log times never go backwards, whichever thread logs.

The WebSocket has no authentication, under ``--security`` too (that secures Zenoh): a host other than
loopback is served with a warning saying so (``compose.yaml`` binds 0.0.0.0 inside its container and
publishes the port on the host's loopback).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import foxglove

from shared.loopback import is_loopback
from shared.runtime import UserError

from . import client_log
from .stream import SCHEMAS, VizMessage

__all__ = ["LiveServer", "LiveServerError", "url_host"]

log = logging.getLogger(__name__)

CLIENT_BACKLOG = 128
"""Messages the server holds for a client that reads slower than they come (the SDK's default: 1024); beyond it the
oldest are dropped. The view is live: a client behind by more than about a second wants the newest, and each slow
client held 26-45 MB at the default in a review's load test."""


def url_host(host: str) -> str:
    """``host`` as a URL writes it: an IPv6 address in brackets."""
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


class LiveServerError(UserError):
    """The server could not start (e.g. the port is taken); the message names the address."""


class LiveServer:
    """Serves the scene channels on ``ws://HOST:PORT`` to the Foxglove app; a context manager.

    Args:
        port: TCP port (0: any free one; :attr:`port` says which).
        host: Address to bind (loopback by default: anyone who can connect sees the run).
        name: The server's name, shown by the app.
        static: Builds the static scene stamped at a time (ns), e.g. ``SceneStream.static``; sent at start and
            every ``static_period_s`` (None: nothing is re-sent).
        static_period_s: The static scene's period (s), finite and > 0.

    Attributes:
        sent: Messages logged per topic (whether a client was subscribed or not).
    """

    def __init__(self, port: int = 8765, host: str = "127.0.0.1", name: str = "foresight",
                 static: Callable[[int], list[VizMessage]] | None = None, static_period_s: float = 1.0) -> None:
        if not (0 < static_period_s <= threading.TIMEOUT_MAX):  # inf killed the resending thread at its first wait
            raise LiveServerError(f"live view: the static scene's period must be a finite number > 0 s, "
                                  f"got {static_period_s}")
        self._context = foxglove.Context()
        self._channels = {
            topic: foxglove.Channel(topic, schema=foxglove.Schema(name=s.name, encoding=s.encoding, data=s.data),
                                    message_encoding=s.message_encoding, context=self._context)
            for topic, s in SCHEMAS.items()}
        client_log.install()  # a client gone: one INFO line, not an ERROR per message it was not sent
        try:
            self._server = foxglove.start_server(name=name, host=host, port=port, context=self._context,
                                                 message_backlog_size=CLIENT_BACKLOG)
        except Exception as exc:  # the SDK raises its own error types (a taken port: an OSError-like message)
            raise LiveServerError(f"live view: cannot serve on ws://{url_host(host)}:{port}: {exc}") from exc
        self.host = host
        self.port: int = self._server.port
        if not is_loopback(host):
            log.warning("live view: serving ws://%s:%d beyond loopback, without authentication (--security covers "
                        "Zenoh, not this WebSocket): anyone who reaches the port sees the run", url_host(host),
                        self.port)
        self.sent: dict[str, int] = dict.fromkeys(SCHEMAS, 0)
        self._last_time: dict[str, int] = {}
        self._stopped = False
        self._count_lock = threading.Lock()
        self._stop = threading.Event()
        self._static = static
        self._resender = None
        if static is not None:
            self._resender = threading.Thread(target=self._resend, args=(static_period_s,), name="live-static",
                                              daemon=True)
            self._resender.start()

    def _resend(self, period_s: float) -> None:
        assert self._static is not None
        while True:
            try:
                for m in self._static(time.time_ns()):
                    self.log(m)
            except Exception:  # a drawing bug costs the static scene, never the server
                log.exception("live view: the static scene failed")
            if self._stop.wait(period_s):
                return

    @property
    def url(self) -> str:
        """The address to open in the Foxglove app on this machine.

        An IPv6 host in brackets (``ws://[::1]:8765``); a server on every address (0.0.0.0 or ::) at loopback.
        """
        host = {"0.0.0.0": "127.0.0.1", "::": "::1", "[::]": "::1"}.get(self.host, self.host)
        return f"ws://{url_host(host)}:{self.port}"

    def watched(self, topic: str) -> bool:
        """Whether a client subscribes to ``topic`` now."""
        return not self._stopped and self._channels[topic].has_sinks()

    def log(self, message: VizMessage) -> None:
        """Send one encoded scene message to every client subscribed to its topic.

        Its log time is raised to its channel's last one if it is older (a thread that drew it earlier than
        another but logged it later): a channel's times never go backwards.
        """
        if self._stopped:
            return
        topic = message.topic
        with self._count_lock:  # several threads log (Zenoh's per subscriber, the log's, the static resend)
            log_time = max(message.log_time, self._last_time.get(topic, 0))
            self._last_time[topic] = log_time
            self._channels[topic].log(message.data, log_time=log_time)
            self.sent[topic] += 1

    def close(self) -> None:
        """Stop serving (clients are disconnected); idempotent."""
        if not self._stopped:
            self._stopped = True
            self._stop.set()
            if self._resender is not None:
                self._resender.join(5.0)
            self._server.stop()
            for ch in self._channels.values():
                ch.close()

    def __enter__(self) -> LiveServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
