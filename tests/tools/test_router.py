"""``foresight router``: its help shows its own Zenoh defaults; it refuses to listen nowhere or on port 0; it stops
when the process that started it has gone."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from services.processes import free_port
from shared.config import ConfigError
from tools import router
from tools.router import ROUTER_ENDPOINT, check_listen, main


class _Opened(Exception):
    """Raised by the stand-in for ``open_session``: the config the router would have opened its session with."""


def test_help_shows_the_routers_own_zenoh_defaults(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "Zenoh session mode (default: router)" in out
    assert re.search(rf"--listen LISTEN .*\(default: {re.escape(ROUTER_ENDPOINT)}\)", out)
    assert re.search(r"--connect CONNECT .*\(default: empty\)", out)


@pytest.mark.parametrize("listen, message", [
    ([], "empty; a router must listen"),
    (["tcp/127.0.0.1:0"], "asks for a free port"),
    (["tcp/127.0.0.1:00"], "asks for a free port"),  # port 0 however written: the regex took only ':0'
    (["tcp/127.0.0.1:000#iface=lo"], "asks for a free port"),
    (["tcp/127.0.0.1:7447", "udp/[::1]:0"], "'udp/[::1]:0' asks for a free port"),
])
def test_a_router_nobody_could_reach_is_refused(listen, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        check_listen(listen)


def test_a_named_port_is_accepted():
    check_listen([ROUTER_ENDPOINT, "tcp/[::1]:7448", "tcp/127.0.0.1:10"])


@pytest.mark.parametrize("argv", [["--listen", ""], ["--listen", "tcp/127.0.0.1:0"]])
def test_the_command_fails_in_one_line_before_opening_a_session(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("foresight router: error: zenoh.listen:")


def _fake_open(zcfg):
    raise _Opened(zcfg)


def _opened_with(monkeypatch, argv: list[str]):
    """The Zenoh config ``main(argv)`` opens its session with (no session is opened)."""
    monkeypatch.setattr(router, "open_session", _fake_open)
    with pytest.raises(_Opened) as got:
        main(argv)
    return got.value.args[0]


@pytest.mark.parametrize(("variable", "file"), [("peer", ""), ("", "client")])
def test_the_services_mode_from_the_shared_file_or_variable_is_set_aside(monkeypatch, tmp_path, variable, file):
    """``[zenoh] mode = "client"`` made the router a client; FORESIGHT_ZENOH_MODE=peer a peer logging "router
    listening"."""
    for name in ("FORESIGHT_ZENOH_MODE", "FORESIGHT_CONFIG", "FORESIGHT_PARENT_PID"):
        monkeypatch.delenv(name, raising=False)
    if variable:
        monkeypatch.setenv("FORESIGHT_ZENOH_MODE", variable)
    if file:
        (tmp_path / "cell.toml").write_text(f'[zenoh]\nmode = "{file}"\n')  # a client's, shared
        monkeypatch.setenv("FORESIGHT_CONFIG", str(tmp_path / "cell.toml"))
    zcfg = _opened_with(monkeypatch, ["--listen", f"tcp/127.0.0.1:{free_port()}"])
    assert zcfg.mode == "router" and zcfg.connect == []


@pytest.mark.parametrize("mode", ["peer", "client", "hub"])
def test_another_mode_given_to_the_router_itself_is_refused_in_one_line(monkeypatch, capsys, mode):
    monkeypatch.delenv("FORESIGHT_CONFIG", raising=False)
    monkeypatch.setattr(router, "open_session", _fake_open)  # taken, it would not run until a signal
    with pytest.raises(SystemExit) as exc:
        main(["--zenoh-mode", mode])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and err == [f"foresight router: error: --zenoh-mode: '{mode}'; a router runs in "
                                           "router mode (leave the flag out)"]


def test_the_router_takes_every_log_level(monkeypatch):
    """``--log-level ERROR``, which every other command takes, was refused."""
    monkeypatch.delenv("FORESIGHT_CONFIG", raising=False)
    zcfg = _opened_with(monkeypatch, ["--log-level", "ERROR", "--listen", f"tcp/127.0.0.1:{free_port()}"])
    assert zcfg.mode == "router"


def test_a_router_started_by_a_process_that_dies_stops_by_itself(tmp_path):
    """A bench killed by SIGTERM left its router running, re-parented to init, holding its port; the services it
    had started stopped (they watch their parent), the router did not."""
    script = tmp_path / "parent.py"
    script.write_text(
        "import subprocess, sys\n"
        f"r = subprocess.Popen([sys.executable, '-m', 'tools', 'router', '--listen', 'tcp/127.0.0.1:{free_port()}'],"
        f" stderr=open({str(tmp_path / 'router.log')!r}, 'w'), env={{**__import__('os').environ, "
        "'FORESIGHT_PARENT_PID': str(__import__('os').getpid())})\n"
        "print(r.pid, flush=True)\n"
        "import time; time.sleep(3)\n")  # then exits without stopping it
    parent = subprocess.Popen([sys.executable, str(script)], cwd=Path(__file__).resolve().parents[2],
                              stdout=subprocess.PIPE, text=True)
    router = int(parent.stdout.readline())
    try:
        parent.wait(timeout=30)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not _gone(router):
            time.sleep(0.1)
        assert _gone(router), "the router outlived the process that started it"
    finally:
        try:
            os.kill(router, 9)
        except ProcessLookupError:
            pass
    assert "has exited; stopping" in (tmp_path / "router.log").read_text()


def _gone(pid: int) -> bool:
    """Whether ``pid`` has exited (a zombie nobody reaped counts: an init that does not reap keeps them)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except (FileNotFoundError, ProcessLookupError):
        return True
