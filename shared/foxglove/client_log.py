"""The Foxglove SDK's lines about a client that went away, in the live view's words: one per client, at INFO.

The SDK's WebSocket server logs an ERROR for every message it could not send to a client whose connection has
ended: a client that stopped reading, then closed, gave 382 ERROR lines within a second in a review's load test
(six such clients; 1664 over the whole test), for what is an ordinary disconnect. :class:`ClientGoneFilter`, on
the SDK's per-client logger, lets the first of a client's lines through as one INFO line naming the client and the
reason, and counts the others (:attr:`ClientGoneFilter.quieted`). On the server's logger it rewords a connection
that closed or spoke no WebSocket (``Dropping client ...: handshake failed``: a port check, a browser, a scanner)
to INFO the same way: 20 raw TCP connects to the live view gave 20 ERROR lines. Any other line of the SDK is left
as it is.
"""

from __future__ import annotations

import logging
import re
import threading
from collections import OrderedDict

__all__ = ["ClientGoneFilter", "CLIENT_LOGGER", "SERVER_LOGGER", "install"]

CLIENT_LOGGER = "foxglove.websocket.connected_client.poller"
"""The SDK's logger (its Rust module path) of the lines about one client's connection."""
SERVER_LOGGER = "foxglove.websocket.server"
"""The SDK's logger of the server's own lines (a connection dropped before its WebSocket handshake among them)."""

_GONE = re.compile(r"Error (?:sending message to|receiving from) client (\S+): (.*)", re.DOTALL)
_NO_HANDSHAKE = re.compile(r"Dropping client (\S+?):? handshake failed(.*)", re.DOTALL)
_KEEP = 256
"""Clients remembered as said (the oldest forgotten first)."""


class ClientGoneFilter(logging.Filter):
    """First line per client kept (as INFO, reworded), the rest counted in :attr:`quieted`."""

    def __init__(self) -> None:
        super().__init__()
        self._said: OrderedDict[str, None] = OrderedDict()
        self._lock = threading.Lock()
        self.quieted = 0

    def filter(self, record: logging.LogRecord) -> bool:
        """Whether to log ``record``: all but a client's later send or receive errors (a dropped handshake: at INFO)."""
        text = record.getMessage()
        m = _GONE.match(text)
        if m is None:
            h = _NO_HANDSHAKE.match(text)
            if h is None:
                return True
            client = h.group(1)  # each connection its own address: one line each, as INFO
            record.msg, record.args = (f"live view: dropped {client}, which closed or spoke no WebSocket before the "
                                       f"handshake (not a Foxglove client: a port check, a browser){h.group(2)}"), ()
            record.levelno, record.levelname = logging.INFO, "INFO"
            return True
        client, why = m.groups()
        with self._lock:
            if client in self._said:
                self.quieted += 1
                return False
            self._said[client] = None
            while len(self._said) > _KEEP:
                self._said.popitem(last=False)
        record.msg, record.args = (f"live view: client {client} went away ({why}); its later send errors are not "
                                   "logged"), ()
        record.levelno, record.levelname = logging.INFO, "INFO"
        return True


_installed: ClientGoneFilter | None = None
_install_lock = threading.Lock()


def install() -> ClientGoneFilter:
    """The process's one filter on :data:`CLIENT_LOGGER` and :data:`SERVER_LOGGER` (added on the first call)."""
    global _installed
    with _install_lock:
        if _installed is None:
            _installed = ClientGoneFilter()
            for name in (CLIENT_LOGGER, SERVER_LOGGER):
                logging.getLogger(name).addFilter(_installed)
        return _installed
