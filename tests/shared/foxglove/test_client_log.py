"""The SDK's lines about a client gone: one INFO line per client (shared/foxglove/client_log.py)."""

from __future__ import annotations

import logging

from shared.foxglove.client_log import CLIENT_LOGGER, ClientGoneFilter, install


def test_a_gone_clients_errors_are_one_info_line_and_other_lines_are_left_alone(caplog) -> None:
    """Six clients that stopped reading, then closed, gave 382 ERROR lines within a second (a review's load test)."""
    logger = logging.getLogger("test.foxglove.client_log")
    gone = ClientGoneFilter()
    logger.addFilter(gone)
    try:
        caplog.set_level(logging.INFO, logger=logger.name)
        for _ in range(50):
            logger.error("Error sending message to client 127.0.0.1:45876: IO error: Broken pipe (os error 32)")
        logger.error("Error receiving from client [::1]:5000: WebSocket protocol error: Connection reset without "
                     "closing handshake")
        logger.error("something else went wrong")
        logger.info("outbox for client 127.0.0.1:45876 full")
    finally:
        logger.removeFilter(gone)
    lines = [(r.levelname, r.getMessage()) for r in caplog.records]
    assert lines[0] == ("INFO", "live view: client 127.0.0.1:45876 went away (IO error: Broken pipe (os error 32)); "
                                "its later send errors are not logged")
    assert lines[1][0] == "INFO" and "client [::1]:5000 went away (WebSocket protocol error" in lines[1][1]
    assert lines[2:] == [("ERROR", "something else went wrong"), ("INFO", "outbox for client 127.0.0.1:45876 full")]
    assert gone.quieted == 49


def test_the_filter_is_installed_once_on_the_sdks_client_logger() -> None:
    first = install()
    assert install() is first and first in logging.getLogger(CLIENT_LOGGER).filters


def test_connections_that_never_handshake_are_info_lines_not_errors(caplog) -> None:
    """20 raw TCP connects to the live view gave 20 ``ERROR ... Dropping client ...: handshake failed`` lines."""
    import socket
    import time

    from shared.foxglove.live import LiveServer

    caplog.set_level(logging.DEBUG)
    with LiveServer(port=0) as server:
        for _ in range(3):
            socket.create_connection(("127.0.0.1", server.port), timeout=2).close()
        with socket.create_connection(("127.0.0.1", server.port), timeout=2) as s:
            s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")  # HTTP, no WebSocket upgrade
            s.recv(1024)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and sum("handshake" in r.getMessage() for r in caplog.records) < 4:
            time.sleep(0.05)
    dropped = [r for r in caplog.records if "handshake" in r.getMessage()]
    assert len(dropped) == 4 and all(r.levelno == logging.INFO for r in dropped), [
        (r.levelname, r.getMessage()) for r in dropped]
    assert all(r.getMessage().startswith("live view: dropped 127.0.0.1:") for r in dropped)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING and r.name.startswith("foxglove")]
