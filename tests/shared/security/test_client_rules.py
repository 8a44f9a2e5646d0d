"""Real sessions on loopback: a client session exchanges nothing with a remote that is not its router.

Every role's certificate names the same hosts, so a machine that answers at the router's address with another
role's certificate passes TLS. A client's access control names the router only: such an impostor reads none of
the client's puts and injects nothing into it, even with the certificate of the role that owns a key.
"""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path

import pytest
import zenoh

from services.processes import free_port
from shared.config import ZenohConfig
from shared.security.acl import ROLES
from shared.security.certificates import init_security_dir
from shared.transport import open_session

STATE, PLAN = "foresight/robot/state", "foresight/planner/plan"


@pytest.fixture(scope="module")
def security(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("security") / "cell"
    init_security_dir(d, ROLES)
    return d


class Inbox:
    def __init__(self) -> None:
        self.lock, self.got = threading.Lock(), set()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.got.add(sample.payload.to_bytes().decode())


def _exchange(security: Path, remote_role: str) -> tuple[set[str], set[str]]:
    """A router-mode session presenting ``remote_role`` and a client planner: what each received of the other's."""
    port = free_port()
    with contextlib.ExitStack() as stack:
        remote = stack.enter_context(open_session(ZenohConfig(
            mode="router", listen=[f"tcp/127.0.0.1:{port}"], connect=[], security_dir=str(security),
            role=remote_role)))
        heard_by_remote, heard_by_planner = Inbox(), Inbox()
        remote.declare_subscriber(PLAN, heard_by_remote)
        planner = stack.enter_context(open_session(ZenohConfig(
            mode="client", listen=[], connect=[f"tcp/127.0.0.1:{port}"], security_dir=str(security), role="planner")))
        planner.declare_subscriber(STATE, heard_by_planner)
        time.sleep(1.0)
        planner.put(PLAN, "plan from the planner")
        remote.put(STATE, f"state from a {remote_role} at the router's address")
        time.sleep(1.0)
        return heard_by_remote.got, heard_by_planner.got


def test_the_router_exchanges_with_a_client(security: Path) -> None:
    """The control: the genuine router receives the client's plan and delivers state to it."""
    assert _exchange(security, "router") == ({"plan from the planner"}, {"state from a router at the router's address"})


@pytest.mark.parametrize("impostor", ["observer", "executor"])
def test_another_role_at_the_routers_address_reads_and_injects_nothing(security: Path, impostor: str) -> None:
    """Before, the observer read the plan, and the executor's certificate (which owns the state) injected state."""
    assert _exchange(security, impostor) == (set(), set())
