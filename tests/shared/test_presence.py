"""A ``stop_with`` peer's departure counts only when this session kept its link (shared/presence.py)."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

import shared.presence as presence
from services.processes import free_port
from shared.config import ZenohConfig
from shared.presence import Presence
from shared.protocol import Keys
from shared.transport import open_session


@dataclass
class Cell:
    """A planner that stops with the executor, the executor's session, and this session's link (a switch)."""

    watcher: Presence
    other: object
    keys: Keys
    stop: threading.Event
    link: threading.Event

    def executor(self) -> Presence:
        """The executor's token, (re)declared on the other session."""
        return Presence(self.other, self.keys, "executor")


@pytest.fixture
def cell(zenoh_hub, wait_until) -> Iterator[Cell]:
    """Two loopback sessions; the planner's link is what ``link`` says (set: linked)."""
    link, stop = threading.Event(), threading.Event()
    link.set()
    with open_session(zenoh_hub()) as sa, open_session(zenoh_hub()) as sb:
        watcher = Presence(sa, Keys("p"), "planner", stop_with=["executor"], stop=stop, is_connected=link.is_set)
        try:
            yield Cell(watcher, sb, Keys("p"), stop, link)
        finally:
            watcher.close()


def test_a_token_lost_with_the_link_is_not_a_departure(cell: Cell, wait_until, monkeypatch) -> None:
    """The router's restart deleted every remote token: each --stop-with service stopped for good."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 0.1)
    executor = cell.executor()
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    cell.link.clear()                           # this session lost its link; the peer's token went with it
    executor.close()
    assert wait_until(lambda: not cell.watcher.is_alive("executor"), 10.0)
    assert not cell.stop.wait(1.0)              # ten grace periods later: still running, waiting for the link
    executor = cell.executor()
    cell.link.set()                             # linked again, and the peer is back
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    assert not cell.stop.wait(0.5)
    executor.close()                            # now it really leaves, the link up: a departure
    assert cell.stop.wait(5.0)


def test_a_peer_gone_while_the_link_is_down_counts_once_the_link_is_back(cell: Cell, wait_until,
                                                                        monkeypatch) -> None:
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 0.1)
    monkeypatch.setattr(presence, "REJOIN_S", 0.3)
    executor = cell.executor()
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    cell.link.clear()
    executor.close()
    assert not cell.stop.wait(0.5)
    cell.link.set()                             # back, and the executor did not come back with it
    assert cell.stop.wait(5.0)


def test_without_any_link_a_departure_counts_after_a_bounded_wait(cell: Cell, wait_until, monkeypatch) -> None:
    """A cell whose only link was the departed peer itself: it ends, after CUT_WAIT_S."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 0.1)
    monkeypatch.setattr(presence, "CUT_WAIT_S", 0.3)
    executor = cell.executor()
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    cell.link.clear()                           # and it never comes back
    executor.close()
    assert cell.stop.wait(5.0)


def test_a_peer_that_reconnects_after_this_session_is_not_taken_for_gone(cell: Cell, wait_until,
                                                                          monkeypatch) -> None:
    """Two clients of a restarted router reconnect at different times: the link back at 0.5 s and the executor's token
    at 1.4 s stopped the planner (the grace ran from the token's deletion; the link was looked at once, at its end)."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 1.0)
    executor = cell.executor()
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    cell.link.clear()
    executor.close()                            # the router goes: the link and the executor's token together
    time.sleep(0.5)
    cell.link.set()                             # this session is linked again first ...
    assert not cell.stop.wait(0.9)              # ... past the 1 s grace from the deletion
    executor = cell.executor()                  # the executor's comes back later
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    assert not cell.stop.wait(1.5)
    executor.close()


def test_a_peer_that_was_the_link_and_withdrew_its_token_has_gone(cell: Cell, wait_until, monkeypatch) -> None:
    """Peer mode, the executor listening and the others connected to it (the README's one-service block): it withdraws
    its token as it ends, and its link goes a moment later. That is a departure (the planner waited for its link)."""
    monkeypatch.setattr(presence, "DEPARTURE_GRACE_S", 1.0)
    executor = cell.executor()
    assert wait_until(lambda: cell.watcher.is_alive("executor"), 10.0)
    executor.close()                            # withdrawn, the link still up
    time.sleep(0.7)
    cell.link.clear()                           # ... then the link goes: the executor's process has ended
    assert cell.stop.wait(3.0)


def test_a_stop_with_peer_never_seen_is_said(zenoh_hub, monkeypatch, caplog) -> None:
    """A tracker started after the executor had ended waited for it for ever, in silence."""
    monkeypatch.setattr(presence, "UNSEEN_WARN_S", 0.2)
    with caplog.at_level("WARNING", logger="shared.transport"), open_session(zenoh_hub()) as session:
        watcher = Presence(session, Keys("p6"), "tracker", stop_with=["executor"], stop=threading.Event())
        try:
            time.sleep(0.6)
        finally:
            watcher.close()
    said = [r.getMessage() for r in caplog.records if "not seen in" in r.getMessage()]
    assert said == ["tracker: executor not seen in 0 s: this service ends when one of them has come and gone, or when "
                    "stopped"]


def test_a_router_restart_does_not_stop_the_services_that_stop_with_the_executor(wait_until) -> None:
    """Client sessions through a real router, which goes and comes back on its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router_cfg = ZenohConfig(mode="router", listen=[endpoint], connect=[], multicast_scouting=False)
    client = ZenohConfig(mode="client", listen=[], connect=[endpoint], multicast_scouting=False)
    keys, stop = Keys("p4"), threading.Event()

    @contextlib.contextmanager
    def router() -> Iterator[None]:
        up, down = threading.Event(), threading.Event()

        def serve() -> None:
            with open_session(router_cfg):
                up.set()
                down.wait(30)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        try:
            assert up.wait(30)
            yield
        finally:
            down.set()
            thread.join(10)

    with contextlib.ExitStack() as first:
        first.enter_context(router())
        with open_session(client) as sa, open_session(client) as sb:
            watcher = Presence(sa, keys, "planner", stop_with=["executor"], stop=stop)
            executor = Presence(sb, keys, "executor")
            try:
                assert wait_until(lambda: watcher.is_alive("executor"), 10.0)
                first.close()                   # the router goes: every remote token is reported deleted
                assert wait_until(lambda: not watcher.is_alive("executor"), 10.0)
                assert wait_until(lambda: not presence.connected(sa), 10.0)
                with router():                  # ... and comes back on the same endpoint
                    assert wait_until(lambda: watcher.is_alive("executor"), 30.0)
                    assert not stop.is_set()
                    executor.close()            # a real departure still ends the watcher
                    assert stop.wait(10.0)
            finally:
                watcher.close()


def test_a_peers_token_name_cannot_forge_a_log_line(zenoh_hub, wait_until, caplog) -> None:
    """A token ``alive/x<newline>FAKE ... ERROR`` wrote a log line of its own, and ANSI escapes reached the terminal;
    the name is logged escaped, the reaction's failure line too."""

    def fail(peer: str, up: bool) -> None:
        raise RuntimeError("reaction")

    caplog.set_level(logging.INFO, logger="shared.transport")
    keys = Keys("p")
    names = ["x\nFAKE foresight.replayer ERROR injected", "x\x1b[31mred"]
    with open_session(zenoh_hub()) as sa, open_session(zenoh_hub()) as sb:
        watcher = Presence(sa, keys, "planner", on_change=fail)
        tokens = [sb.liveliness().declare_token(f"p/alive/{name}") for name in names]
        try:
            assert wait_until(lambda: all(watcher.is_alive(n) for n in names), 10.0)
        finally:
            for token in tokens:
                token.undeclare()
            watcher.close()
    said = [r.getMessage() for r in caplog.records if "x" in r.getMessage() and "peer" in r.getMessage()]
    assert any("peer x\\nFAKE foresight.replayer ERROR injected appeared" in m for m in said)
    assert any("peer x\\x1b[31mred appeared" in m for m in said)
    assert any("reacting to peer x\\nFAKE" in m for m in said)
    assert not any("\n" in m or "\x1b" in m for m in said)


def test_a_long_wait_for_peers_is_said_as_it_goes(zenoh_hub, monkeypatch, caplog) -> None:
    """A wait said only its start and its end: a minute of silence while a planner compiled read as a hang."""
    monkeypatch.setattr(presence, "WAIT_REPORT_S", 0.2)
    with open_session(zenoh_hub()) as session:
        watcher = Presence(session, Keys("w"), "replayer")
        try:
            with caplog.at_level(logging.INFO, logger="shared.transport"):
                assert watcher.wait_for(["planner"], 0.7) == ["planner"]
        finally:
            watcher.close()
    lines = [r.getMessage() for r in caplog.records]
    still = [line for line in lines if "still waiting for planner" in line]
    assert 2 <= len(still) <= 3 and still[0].startswith("replayer: still waiting for planner (0 s of at most 1 s)")
    assert lines[-1].startswith("replayer: starting without planner")
