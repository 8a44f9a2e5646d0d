"""LiveServer: a client of Foxglove's WebSocket protocol sees every scene channel advertised, gets what it
subscribed to byte for byte, and is disconnected when the server stops; a taken port is named."""

from __future__ import annotations

import math
import socket
import time

import pytest

from shared.foxglove.client import FoxgloveClient
from shared.foxglove.live import LiveServer, LiveServerError, url_host
from shared.foxglove.stream import SCHEMAS, SceneStream

from .conftest import occupancy, posterior

T = 1_700_000_000_000_000_000


def test_a_client_gets_every_channel_and_the_messages_it_subscribed_to(builder) -> None:
    stream = SceneStream(builder)
    with LiveServer(port=0) as server:
        assert server.url == f"ws://127.0.0.1:{server.port}" and server.port > 0
        with FoxgloveClient(server.url) as client:
            assert client.server_info["name"] == "foresight"
            advertised = {ch["topic"]: ch for ch in client.channels.values()}
            assert set(advertised) == set(SCHEMAS)
            for topic, ch in advertised.items():  # what the app needs to decode: the schema the SDK carries
                s = SCHEMAS[topic]
                assert (ch["schemaName"], ch["encoding"], ch["schemaEncoding"]) == (s.name, s.message_encoding,
                                                                                     s.encoding)
            assert set(client.subscribe(["/viz/occupancy", "/viz/posterior"])) == {"/viz/occupancy", "/viz/posterior"}
            sent = stream.draw(occupancy(), T) + stream.draw(posterior(), T + 1) + stream.static(T + 2)
            wanted = [(m.topic, m.log_time, m.data) for m in sent if m.topic in ("/viz/occupancy", "/viz/posterior")]
            got: list = []
            deadline = time.monotonic() + 20
            while not got and time.monotonic() < deadline:  # until the subscription has reached the server
                for m in sent:
                    server.log(m)
                got = [(r.topic, r.log_time, r.data) for r in client.receive(0.2)]
            assert got[:2] == wanted  # byte for byte, in order; nothing of the channels not subscribed to
            assert {t for t, _, _ in got} <= {"/viz/occupancy", "/viz/posterior"}
            assert server.sent["/viz/scene"] >= 1  # sent, though nobody subscribed
        server.close()
        server.close()  # idempotent


def test_the_server_stops_with_its_owner_and_its_clients_are_disconnected(builder) -> None:
    server = LiveServer(port=0)
    with FoxgloveClient(server.url) as client:
        client.subscribe()
        server.close()
        deadline = time.monotonic() + 20
        while not client.closed and time.monotonic() < deadline:
            client.receive(0.2)
        assert client.closed
    assert _bindable_within(server.port, 10.0)  # the port is free again


def _bindable_within(port: int, timeout_s: float) -> bool:
    """Whether 127.0.0.1:port can be bound within timeout_s: the server's socket may close a moment after
    its clients are told, and under xdist another worker can hold the same ephemeral port for a while."""
    deadline = time.monotonic() + timeout_s
    while True:
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(("127.0.0.1", port))
                return True
            except OSError:
                if time.monotonic() > deadline:
                    return False
        time.sleep(0.1)


def test_a_taken_port_is_named() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(LiveServerError, match=f"ws://127.0.0.1:{port}"):
            LiveServer(port=port)


def test_an_ipv6_host_is_written_in_brackets() -> None:
    """``ws://::1:8765`` is no address; the view printed it for ``--host ::1``."""
    assert url_host("::1") == "[::1]" and url_host("[::1]") == "[::1]"
    assert url_host("127.0.0.1") == "127.0.0.1" and url_host("localhost") == "localhost"


@pytest.mark.parametrize("period", [math.inf, math.nan, 0.0, -1.0])
def test_a_static_period_that_is_not_a_finite_positive_number_is_refused(period) -> None:
    """An infinite period killed the thread re-sending the table and cups (time_t overflow) at its first wait."""
    with pytest.raises(LiveServerError, match="period must be a finite number > 0"):
        LiveServer(port=0, static=lambda t: [], static_period_s=period)


def test_a_channel_s_log_times_never_go_backwards_and_watched_says_who_subscribes(builder) -> None:
    """A thread that drew a message earlier than another but logged it later sent an older log time after a newer
    one on the same channel; the view also drew for channels nobody watched."""
    stream = SceneStream(builder)
    with LiveServer(port=0) as server, FoxgloveClient(server.url) as client:
        assert not server.watched("/viz/posterior")
        client.subscribe(["/viz/posterior"])
        deadline = time.monotonic() + 20
        while not server.watched("/viz/posterior") and time.monotonic() < deadline:
            client.receive(0.1)
        assert server.watched("/viz/posterior") and not server.watched("/viz/occupancy")
        late, early = stream.draw(posterior(), T + 5)[0], stream.draw(posterior(), T + 1)[0]
        server.log(late)
        server.log(early)  # drawn before `late`, logged after it
        got: list = []
        while len(got) < 2 and time.monotonic() < deadline:
            got += [r.log_time for r in client.receive(0.2)]
        assert got == [T + 5, T + 5]
    assert not server.watched("/viz/posterior")  # stopped: nobody


def test_a_host_beyond_loopback_is_served_with_a_warning_and_opened_at_loopback(monkeypatch, caplog) -> None:
    """The WebSocket has no authentication, --security or not; 0.0.0.0 was served silently and printed as the
    address to open. (The server is not really started on 0.0.0.0 here: tests stay on loopback.)"""
    import foxglove

    started = []

    class Fake:
        port = 8765

        def stop(self) -> None:
            pass

    monkeypatch.setattr(foxglove, "start_server", lambda **kw: started.append(kw["host"]) or Fake())
    with caplog.at_level("WARNING", logger="shared.foxglove.live"):
        for host, url in (("0.0.0.0", "ws://127.0.0.1:8765"), ("::", "ws://[::1]:8765"),
                          ("192.0.2.7", "ws://192.0.2.7:8765"), ("127.0.0.1", "ws://127.0.0.1:8765")):
            caplog.clear()
            with LiveServer(port=8765, host=host) as server:
                assert server.url == url
            warned = [r.getMessage() for r in caplog.records]
            assert (host == "127.0.0.1") == (not warned), (host, warned)
            assert all("without authentication" in w and "--security" in w for w in warned)
    assert started == ["0.0.0.0", "::", "192.0.2.7", "127.0.0.1"]
