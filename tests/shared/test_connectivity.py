"""A session that reaches no router or peer says so within seconds, retries, and gives up only when asked
(issue 12, item 4). Loopback only, on a port nobody listens on."""

from __future__ import annotations

import dataclasses
import logging
import threading

import pytest

from services.processes import free_port
from shared.config import ZenohConfig
from shared.connectivity import FIRST_REPORT_S, MAX_REPORT_S, ConnectionWatch
from shared.transport import StoppedWhileConnecting, TransportError, open_session, open_with_retry


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _messages(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "foresight.connectivity"]


def test_reports_back_off_and_stay_bounded(caplog):
    caplog.set_level(logging.INFO, logger="foresight.connectivity")
    clock = FakeClock()
    cfg = ZenohConfig(connect=["tcp/127.0.0.1:1"])
    watch = ConnectionWatch(lambda: False, cfg, "replayer", clock=clock)
    reported_at = []
    for step in range(0, 4 * 60 * 4):  # 4 minutes in 0.25 s polls
        clock.t = step * 0.25
        before = watch.warnings
        watch.poll(False)
        if watch.warnings > before:
            reported_at.append(clock.t)
    assert reported_at[0] == FIRST_REPORT_S
    gaps = [b - a for a, b in zip(reported_at, reported_at[1:], strict=False)]
    assert gaps[:4] == [3.0, 6.0, 12.0, 24.0] and max(gaps) == MAX_REPORT_S
    first = _messages(caplog)[0]
    assert first == ("replayer: no router or peer at tcp/127.0.0.1:1 after 3 s; Zenoh retries every 1-4 s; "
                     "next report in 3 s")
    # something answers: said once; then everything drops: said at once
    watch.poll(True)
    watch.poll(True)
    watch.poll(False)
    msgs = _messages(caplog)
    assert sum("connected to tcp/127.0.0.1:1" in m for m in msgs) == 1
    assert msgs[-1].startswith("replayer: lost every router and peer (tcp/127.0.0.1:1)")
    assert watch.failed is None


def test_require_connection_gives_up_once_and_stops_the_service():
    clock = FakeClock()
    stop = threading.Event()
    cfg = ZenohConfig(connect=["tcp/127.0.0.1:1"], require_connection=True, connect_timeout_s=5.0)
    watch = ConnectionWatch(lambda: False, cfg, "planner", stop=stop, clock=clock)
    for step in range(40):
        clock.t = step * 0.25
        watch.poll(False)
    assert stop.is_set()
    assert watch.failed == ("planner: gave up: no router or peer at tcp/127.0.0.1:1 within 5 s "
                            "(zenoh.require_connection)")
    # once connected, a later loss never gives up (it retries and reports)
    ok = ConnectionWatch(lambda: True, cfg, "planner", stop=threading.Event(), clock=clock)
    ok.poll(True)
    clock.t += 100
    ok.poll(False)
    clock.t += 100
    ok.poll(False)
    assert ok.failed is None and not ok.stop.is_set()


def test_peer_with_an_unreachable_router_says_so_then_connects_when_it_listens(caplog, wait_until):
    caplog.set_level(logging.INFO, logger="foresight.connectivity")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    peer = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint])
    with open_session(peer, name="predictor"):
        assert wait_until(lambda: any("no router or peer at " + endpoint in m for m in _messages(caplog)), 20.0), \
            _messages(caplog)
        router = ZenohConfig(mode="router", listen=[endpoint], connect=[])
        with open_session(router):
            # Zenoh retries the endpoint in the background (at most every 4 s); the watch says when it answers
            assert wait_until(lambda: any(f"predictor: connected to {endpoint}" in m for m in _messages(caplog)),
                             30.0), _messages(caplog)


def test_require_connection_ends_the_session_with_one_line():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stop = threading.Event()
    peer = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], require_connection=True,
                       connect_timeout_s=0.5)
    began = []
    with pytest.raises(TransportError, match=rf"^executor: gave up: no router or peer at {endpoint} within 0\.5 s"):
        with open_session(peer, stop, "executor"):
            began.append(True)
    assert stop.is_set(), "the watch sets the service's stop event"
    assert began == []  # the service's work never began (a review's executor wrote an MCAP, then gave up)


def test_require_connection_begins_the_work_once_connected():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = ZenohConfig(mode="router", listen=[endpoint], connect=[])
    peer = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], require_connection=True,
                       connect_timeout_s=30.0)
    with open_session(router), open_session(peer, threading.Event(), "executor") as session:
        assert ConnectionWatch.reaches(session)  # connected before the body


def test_client_retries_end_when_the_service_is_stopped():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    client = ZenohConfig(mode="client", listen=[], connect=[endpoint], connect_timeout_s=600.0)
    stop = threading.Event()
    timer = threading.Timer(0.5, stop.set)
    timer.start()
    try:
        with pytest.raises(StoppedWhileConnecting, match=rf"^stopped while waiting for the router {endpoint}$"):
            open_with_retry(client, stop=stop)
    finally:
        timer.cancel()


def test_the_endpoints_are_named_as_the_session_uses_them() -> None:
    """Under security the warnings said 'router tcp/...' though every link was TLS (docs/security.md: tls/...)."""
    from shared.connectivity import connect_names

    plain = ZenohConfig(mode="client", connect=["tcp/127.0.0.1:7447", "tcp/[::1]:7447"], multicast_scouting=False)
    assert connect_names(plain) == "tcp/127.0.0.1:7447,tcp/[::1]:7447"
    secured = dataclasses.replace(plain, security_dir="cell")
    assert connect_names(secured) == "tls/127.0.0.1:7447,tls/[::1]:7447"
