"""is_loopback: the one test behind the warnings about serving beyond this machine."""

from __future__ import annotations

import pytest

from shared.loopback import is_loopback


@pytest.mark.parametrize("host, expected", [
    ("127.0.0.1", True), ("127.1.2.3", True), ("::1", True), ("[::1]", True), ("localhost", True),
    ("LOCALHOST", True), ("0.0.0.0", False), ("::", False), ("192.168.1.5", False), ("robot.local", False),
    ("", False),
])
def test_only_loopback_addresses_and_localhost_are_loopback(host, expected) -> None:
    assert is_loopback(host) is expected
