"""A ``stop_with`` peer's departure counts only when this session kept its link (shared/presence.py)."""

from __future__ import annotations

import threading
import time

import shared.presence as presence
from services.processes import free_port
from shared.config import ZenohConfig
from shared.presence import Presence
from shared.protocol import Keys
from shared.transport import open_session


def wait_until(cond, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_a_token_lost_with_the_link_is_not_a_departure(zenoh_hub, monkeypatch) -> None:
    """The router's restart deleted every remote token: each --stop-with service stopped for good."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 0.1)
    link = threading.Event()
    link.set()
    keys, stop = Keys("p1"), threading.Event()
    with open_session(zenoh_hub()) as sa, open_session(zenoh_hub()) as sb:
        watcher = Presence(sa, keys, "planner", stop_with=["executor"], stop=stop, is_connected=link.is_set)
        try:
            executor = Presence(sb, keys, "executor")
            assert wait_until(lambda: watcher.is_alive("executor"))
            link.clear()                        # this session lost its link; the peer's token went with it
            executor.close()
            assert wait_until(lambda: not watcher.is_alive("executor"))
            assert not stop.wait(1.0)           # ten grace periods later: still running, waiting for the link
            executor = Presence(sb, keys, "executor")
            link.set()                          # linked again, and the peer is back
            assert wait_until(lambda: watcher.is_alive("executor"))
            assert not stop.wait(0.5)
            executor.close()                    # now it really leaves, the link up: a departure
            assert stop.wait(5.0)
        finally:
            watcher.close()


def test_a_peer_gone_while_the_link_is_down_counts_once_the_link_is_back(zenoh_hub, monkeypatch) -> None:
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 0.1)
    monkeypatch.setattr(presence, "REJOIN_S", 0.3)
    link = threading.Event()
    keys, stop = Keys("p2"), threading.Event()
    with open_session(zenoh_hub()) as sa, open_session(zenoh_hub()) as sb:
        watcher = Presence(sa, keys, "planner", stop_with=["executor"], stop=stop, is_connected=link.is_set)
        try:
            link.set()
            executor = Presence(sb, keys, "executor")
            assert wait_until(lambda: watcher.is_alive("executor"))
            link.clear()
            executor.close()
            assert not stop.wait(0.5)
            link.set()                          # back, and the executor did not come back with it
            assert stop.wait(5.0)
        finally:
            watcher.close()


def test_without_any_link_a_departure_counts_after_a_bounded_wait(zenoh_hub, monkeypatch) -> None:
    """A cell whose only link was the departed peer itself: it ends, after CUT_WAIT_S."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 0.1)
    monkeypatch.setattr(presence, "CUT_WAIT_S", 0.3)
    keys, stop = Keys("p3"), threading.Event()
    with open_session(zenoh_hub()) as sa, open_session(zenoh_hub()) as sb:
        watcher = Presence(sa, keys, "planner", stop_with=["executor"], stop=stop, is_connected=lambda: False)
        try:
            executor = Presence(sb, keys, "executor")
            assert wait_until(lambda: watcher.is_alive("executor"))
            executor.close()
            assert stop.wait(5.0)
        finally:
            watcher.close()


def test_a_router_restart_does_not_stop_the_services_that_stop_with_the_executor() -> None:
    """Client sessions through a real router, which goes and comes back on its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router_cfg = ZenohConfig(mode="router", listen=[endpoint], connect=[], multicast_scouting=False)
    client = ZenohConfig(mode="client", listen=[], connect=[endpoint], multicast_scouting=False)
    keys, stop = Keys("p4"), threading.Event()
    router_stop = threading.Event()

    def router() -> None:
        with open_session(router_cfg) as _:
            router_stop.wait(30)

    first = threading.Thread(target=router, daemon=True)
    first.start()
    with open_session(client) as sa, open_session(client) as sb:
        watcher = Presence(sa, keys, "planner", stop_with=["executor"], stop=stop)
        executor = Presence(sb, keys, "executor")
        try:
            assert wait_until(lambda: watcher.is_alive("executor"))
            router_stop.set()                   # the router goes: every remote token is reported deleted
            first.join(10)
            assert wait_until(lambda: not watcher.is_alive("executor"))
            assert wait_until(lambda: not presence.connected(sa))
            router_stop.clear()
            second = threading.Thread(target=router, daemon=True)
            second.start()                      # ... and comes back on the same endpoint
            assert wait_until(lambda: watcher.is_alive("executor"), timeout=30.0)
            assert not stop.is_set()
            executor.close()                    # a real departure still ends the watcher
            assert stop.wait(10.0)
        finally:
            watcher.close()
            router_stop.set()
            second.join(10)


def test_a_peer_that_reconnects_after_this_session_is_not_taken_for_gone(zenoh_hub, monkeypatch) -> None:
    """Two clients of a restarted router reconnect at different times: the link back at 0.5 s and the executor's token
    at 1.4 s stopped the planner (the grace ran from the token's deletion; the link was looked at once, at its end)."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 1.0)
    link = threading.Event()
    link.set()
    keys, stop = Keys("p5"), threading.Event()
    with open_session(zenoh_hub()) as sa, open_session(zenoh_hub()) as sb:
        watcher = Presence(sa, keys, "planner", stop_with=["executor"], stop=stop, is_connected=link.is_set)
        try:
            executor = Presence(sb, keys, "executor")
            assert wait_until(lambda: watcher.is_alive("executor"))
            link.clear()
            executor.close()                    # the router goes: the link and the executor's token together
            time.sleep(0.5)
            link.set()                          # this session is linked again first ...
            assert not stop.wait(0.9)           # ... past the 1 s grace from the deletion
            executor = Presence(sb, keys, "executor")  # the executor's comes back later
            assert wait_until(lambda: watcher.is_alive("executor"))
            assert not stop.wait(1.5)
            executor.close()
        finally:
            watcher.close()
