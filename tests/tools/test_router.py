"""``foresight router``: its help shows its own Zenoh defaults; it refuses to listen nowhere or on port 0."""

from __future__ import annotations

import re

import pytest

from shared.config import ConfigError
from tools.router import ROUTER_ENDPOINT, check_listen, main


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
