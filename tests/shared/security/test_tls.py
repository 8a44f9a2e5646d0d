"""Real sessions on loopback: mutual TLS and the generated access control keep every role to its keys.

One router (role ``router``) listens on ``tls/127.0.0.1:PORT``; services connect to it as peers
with their own certificates (made here). Refused: a session with no certificate, one from another
CA, an expired one, plain TCP to the TLS port - each reads nothing and writes nothing; the observer
reads everything and writes nothing; a service cannot put a key it does not own.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import re
import shutil
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from services.processes import free_port
from shared.config import ZenohConfig
from shared.security.acl import ROLES
from shared.security.certificates import CertificateError, Issued, init_security_dir, issue
from shared.security.tls import listen_warning, tls_settings
from shared.transport import TransportError, open_session, open_with_retry

POSE, STATE, PLAN = "foresight/human/pose", "foresight/robot/state", "foresight/planner/plan"


@pytest.fixture(scope="module")
def dirs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("security")
    good, other, expired = root / "good", root / "other", root / "expired"
    init_security_dir(good, ROLES)
    init_security_dir(other, ["replayer"])  # another authority
    shutil.copytree(good, expired)
    old = issue(Issued((good / "ca.crt").read_bytes(), (good / "ca.key").read_bytes()), "replayer",
                not_after=dt.datetime.now(dt.UTC) - dt.timedelta(hours=1))
    (expired / "replayer.crt").write_bytes(old.cert_pem)
    (expired / "replayer.key").write_bytes(old.key_pem)
    return {"good": good, "other": other, "expired": expired}


class Inbox:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.got: list[tuple[str, str]] = []

    def __call__(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.got.append((str(sample.key_expr), sample.payload.to_bytes().decode()))

    def payloads(self) -> set[str]:
        with self.lock:
            return {p for _, p in self.got}


@contextlib.contextmanager
def cell(dirs: dict[str, Path]) -> Iterator[tuple[str, contextlib.ExitStack]]:
    port = free_port()
    with contextlib.ExitStack() as stack:
        stack.enter_context(open_session(ZenohConfig(mode="router", listen=[f"tcp/127.0.0.1:{port}"], connect=[],
                                                     security_dir=str(dirs["good"]), role="router")))
        yield f"tcp/127.0.0.1:{port}", stack


def _session(stack: contextlib.ExitStack, endpoint: str, role: str, security: Path | None) -> zenoh.Session:
    cfg = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], security_dir=str(security or ""),
                      role=role)
    return stack.enter_context(open_session(cfg))


def _raw_tls(endpoint: str, ca: Path, cert: Path | None = None, key: Path | None = None) -> zenoh.Session:
    """A session built by hand, not by Foresight's (which refuses an expired certificate before connecting)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint.replace("tcp/", "tls/")]))
    tls = {"root_ca_certificate": str(ca)}
    if cert is not None and key is not None:
        tls.update(enable_mtls=True, connect_certificate=str(cert), connect_private_key=str(key))
    conf.insert_json5("transport/link/tls", json.dumps(tls))
    return zenoh.open(conf)


def test_roles_are_held_to_the_wire_contract(dirs: dict[str, Path]) -> None:
    with cell(dirs) as (endpoint, stack):
        inboxes = {role: Inbox() for role in ("predictor", "executor", "planner", "observer")}
        sessions = {}
        for role, key in (("predictor", "foresight/human/*"), ("executor", "foresight/**"), ("planner", STATE),
                          ("observer", "foresight/**")):
            sessions[role] = _session(stack, endpoint, role, dirs["good"])
            sessions[role].declare_subscriber(key, inboxes[role])
        replayer = _session(stack, endpoint, "replayer", dirs["good"])
        executor = sessions["executor"]
        time.sleep(1.0)
        replayer.put(POSE, "pose from the replayer")
        executor.put(STATE, "state from the executor")
        sessions["planner"].put(POSE, "pose from the planner")  # not its key
        replayer.put(PLAN, "plan from the replayer")  # not its key
        sessions["predictor"].put(STATE, "state from the predictor")  # not its key
        sessions["observer"].put(STATE, "state from the observer")  # reads only
        time.sleep(1.0)
        got = {role: inbox.payloads() for role, inbox in inboxes.items()}
    assert got["predictor"] == {"pose from the replayer"}
    assert got["planner"] == {"state from the executor"}
    # the observer reads every key (its own put only in its own process: it reached no one else)
    assert got["observer"] == {"pose from the replayer", "state from the executor", "state from the observer"}
    assert got["executor"] == {"pose from the replayer", "state from the executor"}


@pytest.mark.parametrize("intruder", ["no certificate", "another CA", "expired", "plain TCP"])
def test_refused_sessions_read_and_write_nothing(intruder: str, dirs: dict[str, Path]) -> None:
    with cell(dirs) as (endpoint, stack):
        executor = _session(stack, endpoint, "executor", dirs["good"])
        logged = Inbox()
        executor.declare_subscriber("foresight/**", logged)
        if intruder == "no certificate":
            bad = stack.enter_context(_raw_tls(endpoint, dirs["good"] / "ca.crt"))
        elif intruder == "expired":
            d = dirs["expired"]
            bad = stack.enter_context(_raw_tls(endpoint, d / "ca.crt", d / "replayer.crt", d / "replayer.key"))
        else:
            security = {"another CA": dirs["other"], "plain TCP": None}[intruder]
            bad = _session(stack, endpoint, "replayer", security)
        seen = Inbox()
        bad.declare_subscriber("foresight/**", seen)
        replayer = _session(stack, endpoint, "replayer", dirs["good"])
        time.sleep(1.0)
        bad.put(POSE, "intruder pose")
        replayer.put(POSE, "genuine pose")
        time.sleep(1.0)
        assert logged.payloads() == {"genuine pose"}
        assert seen.payloads() <= {"intruder pose"}  # at most its own put, delivered in its own process


def test_a_session_with_an_expired_certificate_fails_at_once_naming_it(dirs: dict[str, Path]) -> None:
    cfg = ZenohConfig(mode="client", listen=[], connect=["tcp/127.0.0.1:9"], security_dir=str(dirs["expired"]),
                      role="replayer")
    with pytest.raises(CertificateError, match="replayer.crt: expired at"):
        with open_session(cfg):
            pass
    assert tls_settings(dirs["good"], "replayer")["close_link_on_expiration"] is True  # and a link ends with it


def test_a_client_that_never_reaches_its_router_under_tls_is_told_what_that_may_mean(dirs, caplog) -> None:
    """The documented deployment (clients): a refused certificate looked like "router not reachable"."""
    cfg = ZenohConfig(mode="client", listen=[], connect=[f"tcp/127.0.0.1:{free_port()}"], multicast_scouting=False,
                      security_dir=str(dirs["good"]), role="planner", connect_timeout_s=0.3)
    with caplog.at_level("WARNING", logger="shared.transport"), pytest.raises(TransportError) as err:
        open_with_retry(cfg, sleep=lambda _s: None)
    hint = "mutual TLS as planner: nothing listens at 127.0.0.1:"
    assert hint in str(err.value) and "foresight security check DIR" in str(err.value)
    assert any(hint in r.getMessage() for r in caplog.records if "not reachable yet" in r.getMessage())
    assert "connect tls/127.0.0.1:" in str(err.value)  # the link as it is made (it said tcp/)



def test_a_plain_client_at_a_secure_routers_port_is_told_it_speaks_tls(dirs) -> None:
    """It was told only that the router was not reachable (a security review): the port answers a TLS handshake."""
    from shared.security.probe import speaks_tls

    with cell(dirs) as (endpoint, _), pytest.raises(TransportError) as err:
        assert speaks_tls(endpoint)
        cfg = ZenohConfig(mode="client", listen=[], connect=[endpoint], multicast_scouting=False, connect_timeout_s=0.3)
        open_with_retry(cfg, sleep=lambda _s: None)
    assert f"{endpoint.removeprefix('tcp/')} speaks TLS: a secure router; give --security DIR" in str(err.value)
    with open_session(ZenohConfig(mode="router", listen=[f"tcp/127.0.0.1:{(port := free_port())}"], connect=[])):
        assert not speaks_tls(f"tcp/127.0.0.1:{port}")  # a plain router
    assert not speaks_tls(f"tcp/127.0.0.1:{free_port()}")  # nothing there

def test_a_session_whose_ca_file_holds_a_second_authority_fails_at_once(dirs: dict[str, Path], tmp_path) -> None:
    """Zenoh trusts every certificate in ca.crt: an authority appended to it had its own 'planner' let in (a
    review's script: the executor took its plans). A session now refuses such a file before it connects."""
    import shutil

    cell = tmp_path / "cell"
    shutil.copytree(dirs["good"], cell)
    cell.chmod(0o700)
    (cell / "ca.crt").write_bytes((cell / "ca.crt").read_bytes() + (dirs["other"] / "ca.crt").read_bytes())
    cfg = ZenohConfig(mode="client", listen=[], connect=["tcp/127.0.0.1:9"], security_dir=str(cell), role="replayer")
    with pytest.raises(CertificateError, match="ca.crt: holds 2 certificates"):
        with open_session(cfg):
            pass


def test_a_session_listening_on_a_host_its_certificate_does_not_name_is_warned(dirs) -> None:
    """Every peer connecting there refuses the link (names are verified): said at start, not at the first link."""
    def cfg(*listen: str) -> ZenohConfig:
        return ZenohConfig(mode="peer", listen=list(listen), connect=[], multicast_scouting=False,
                           security_dir=str(dirs["good"]), role="router")

    assert listen_warning(cfg("tcp/127.0.0.1:0", "tcp/localhost:7447", "tcp/0.0.0.0:7447", "tcp/[::]:7447")) == ""
    warning = listen_warning(cfg("tcp/127.0.0.1:0", "tcp/192.168.1.10:7447"))
    assert warning.startswith("listening on tls/192.168.1.10:7447, which router.crt does not name (it names "
                              "127.0.0.1, localhost)") and "--hosts" in warning  # tls/: what it listens on
    plain = ZenohConfig(mode="peer", listen=["tcp/192.168.1.10:7447"], connect=[], multicast_scouting=False)
    assert "without security" in listen_warning(plain)


def test_a_wildcard_certificate_names_the_hosts_one_label_below_it(tmp_path: Path) -> None:
    """Certificates made with --hosts '*.robot.lan' warned of listening on a.robot.lan, which every peer accepts."""
    from shared.security.tls import names_host

    init_security_dir(tmp_path / "cell", ["router"], hosts=["*.robot.lan"])

    def warned(host: str) -> bool:
        return bool(listen_warning(ZenohConfig(mode="peer", listen=[f"tcp/{host}:7447"], connect=[],
                                               security_dir=str(tmp_path / "cell"), role="router")))

    assert not warned("a.robot.lan") and not warned("A.Robot.LAN")
    assert warned("robot.lan") and warned("a.b.robot.lan") and warned("a.robot.land")
    assert names_host({"*.robot.lan"}, "a.robot.lan") and not names_host({"*.0.0.1"}, "127.0.0.1")  # no address


def test_a_refused_link_is_named_by_one_handshake(dirs: dict[str, Path], tmp_path: Path) -> None:
    """Router down, its certificate from another authority, for another name, or this machine's refused: the client's
    warnings said the same generic line for all of them (a four-machine review)."""
    from shared.security.probe import diagnose

    mixed = tmp_path / "mixed"  # this cell's ca.crt, another authority's replayer certificate
    mixed.mkdir(mode=0o700)
    shutil.copy(dirs["good"] / "ca.crt", mixed / "ca.crt")
    for name in ("replayer.crt", "replayer.key"):
        shutil.copy(dirs["other"] / name, mixed / name)
    port = free_port()
    assert diagnose(f"tls/127.0.0.1:{port}", dirs["good"], "planner") == \
        f"nothing listens at 127.0.0.1:{port} (connection refused)"
    with cell(dirs) as (endpoint, _):
        ep = endpoint.replace("tcp/", "tls/")
        assert "succeeds (the router accepts this certificate)" in diagnose(ep, dirs["good"], "planner")
        assert "presents is not issued by this cell's authority (ca.crt) (unable to get local issuer certificate)" \
            in diagnose(ep, dirs["other"], "replayer")
        assert diagnose(ep, mixed, "replayer") == "replayer.crt is not signed by ca.crt (InvalidSignature)"  # ours
        cfg = ZenohConfig(mode="client", listen=[], connect=[endpoint], multicast_scouting=False,
                          security_dir=str(dirs["other"]), role="replayer", connect_timeout_s=0.3)
        with pytest.raises(TransportError, match="not issued by this cell's authority"):
            open_with_retry(cfg, sleep=lambda _s: None)
    port = free_port()  # a router listening on a loopback address its certificate does not name
    with open_session(ZenohConfig(mode="router", listen=[f"tcp/127.0.0.2:{port}"], connect=[],
                                  security_dir=str(dirs["good"]), role="router")):
        assert "issued for other names" in diagnose(f"tls/127.0.0.2:{port}", dirs["good"], "planner")


def _within(seconds: float, condition) -> bool:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.1)
    return True


def test_a_certificate_expiring_while_the_service_runs_is_named_and_renewing_it_reconnects(
        dirs: dict[str, Path], tmp_path: Path) -> None:
    """A client whose planner.crt expired while it ran blamed the router every few seconds ("refused this machine's
    planner certificate (sslv3 alert certificate expired)"). Zenoh reads the files again at each retry: the
    service keeps retrying, and new files written in place bring the link back without a restart."""
    from shared.connectivity import ConnectionWatch
    from shared.security.probe import diagnose

    own = tmp_path / "own"
    shutil.copytree(dirs["good"], own)
    authority = Issued((own / "ca.crt").read_bytes(), (own / "ca.key").read_bytes())

    def renew(end: dt.datetime | None) -> None:
        issued = issue(authority, "planner", not_after=end)
        (own / "planner.crt").write_bytes(issued.cert_pem)
        (own / "planner.key").write_bytes(issued.key_pem)

    renew(dt.datetime.now(dt.UTC) + dt.timedelta(seconds=3))
    with cell(dirs) as (endpoint, stack):
        client = stack.enter_context(open_session(ZenohConfig(
            mode="client", listen=[], connect=[endpoint], security_dir=str(own), role="planner", connect_timeout_s=5)))
        assert _within(5, lambda: ConnectionWatch.reaches(client))
        assert _within(10, lambda: not ConnectionWatch.reaches(client))  # closed at the certificate's end
        what = diagnose(endpoint.replace("tcp/", "tls/"), own, "planner")
        assert re.fullmatch(r"planner\.crt: expired at \d{4}-\d\d-\d\d \d\d:\d\d UTC \(this machine's clock: .*\); "
                            r"issue new certificates: .*", what), what
        renew(None)
        assert _within(15, lambda: ConnectionWatch.reaches(client))
