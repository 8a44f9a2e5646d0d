"""Zenoh endpoints parsed strictly: a mistyped host or port is refused, not retried for ever."""

from __future__ import annotations

import dataclasses
import re

import pytest

from shared.config import ConfigError, resolve_config
from shared.endpoints import check_host_port, endpoint_host_port, picked_port


@dataclasses.dataclass
class Svc:
    rate_hz: float = 1.0


@pytest.mark.parametrize(("endpoint", "expected"), [
    ("tcp/127.0.0.1:7447", ("127.0.0.1", 7447)),
    ("tls/router.local:7447#iface=lo", ("router.local", 7447)),
    ("tcp/[::1]:7448?rel=1", ("::1", 7448)),
    ("tcp/[fe80::1%eth0]:7447", ("fe80::1%eth0", 7447)),
    ("udp/localhost:0", ("localhost", 0)),
    ("tcp/127.0.0.1:65535", ("127.0.0.1", 65535)),
])
def test_an_endpoints_host_and_port(endpoint: str, expected: tuple[str, int]) -> None:
    assert endpoint_host_port(endpoint) == expected


@pytest.mark.parametrize("endpoint", [
    "127.0.0.1:7447", "tcp/127.0.0.1", "tcp/127.0.0.1:port", "tcp/:7447",
    # int() took these: Zenoh then retried the endpoint for ever
    "tcp/127.0.0.1:7_447", "tcp/127.0.0.1: 7447", "tcp/127.0.0.1:+7447", "tcp/127.0.0.1:\u0667\u0664\u0664\u0667",
    "tcp/127.0.0.1:7447 ", "tcp/127.0.0.1:65536", "tcp/127.0.0.1:-1",
    # hosts no resolver answers for: a space, a control character, an unbracketed ':' (an IPv6 address, a 2nd port)
    "tcp/a b:7447", "tcp/a\tb:7447", "tcp/ 127.0.0.1:7447", "tcp/127.0.0.1:7447:1", "tcp/::1:7447",
    "tcp/[::1:7447", "tcp/[not-v6]:7447", "tcp/[127.0.0.1]:7447",
])
def test_a_malformed_endpoint_is_refused(endpoint: str) -> None:
    pattern = rf"^endpoint {re.escape(repr(endpoint))} is not of the form proto/HOST:PORT: "
    with pytest.raises(ValueError, match=pattern):
        endpoint_host_port(endpoint)


@pytest.mark.parametrize(("option", "endpoint", "why"), [
    ("connect", "tcp/127.0.0.1:7_447", r"the port '7_447' is not a number 0-65535"),
    ("connect", "tcp/127.0.0.1:\u0667\u0664\u0664\u0667", r"the port '.*' is not a number 0-65535"),
    ("connect", "tcp/a b:7447", r"the host 'a b' is empty or has a space or a control character"),
    ("connect", "tcp/127.0.0.1:7447:1", r"the host '127\.0\.0\.1:7447' has a ':' \(an IPv6 .*\)"),
    ("listen", "tcp/127.0.0.1:+7447", r"the port '\+7447' is not a number 0-65535"),
    ("connect", "tcp/127.0.0.1:0", r"port 0 is none to connect to"),
])
def test_the_config_refuses_a_malformed_endpoint_in_one_line(option: str, endpoint: str, why: str) -> None:
    pattern = (rf"^zenoh\.{option}: endpoint {re.escape(repr(endpoint))} is not of the form proto/HOST:PORT "
               rf"\(a port [01]-65535\): {why} \(set by FORESIGHT_ZENOH_{option.upper()}\)$")
    with pytest.raises(ConfigError, match=pattern) as err:
        resolve_config("svc", Svc, env={f"FORESIGHT_ZENOH_{option.upper()}": endpoint})
    assert "\n" not in str(err.value)


def test_a_listen_port_may_be_0_and_a_path_endpoint_has_none() -> None:
    check_host_port("zenoh.listen", "tcp/127.0.0.1:0", lowest=0)
    assert picked_port("tcp/127.0.0.1:0") and not picked_port("tcp/127.0.0.1:7447")
    assert not picked_port("unixsock-stream//tmp/z.sock")
