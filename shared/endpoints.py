"""Zenoh endpoints: ``proto/HOST:PORT`` parsed strictly, so that a mistyped one is refused, not retried for ever.

Zenoh takes ``tcp/127.0.0.1:7_447`` or ``tcp/a b:7447`` and keeps trying to reach it in the background, logging only
that nothing answers; a service configured so waits for a router it can never find. :func:`endpoint_host_port` takes
a port of ASCII digits only (Python's ``int`` also took ``" 7447"``, ``"+7447"``, ``"7_447"`` and other scripts'
digits), a host without spaces or control characters, and an IPv6 host only in brackets (``tcp/[::1]:7447``: in
``tcp/127.0.0.1:7447:1`` the host would have been ``127.0.0.1:7447``).
"""

from __future__ import annotations

import ipaddress
import re

from shared.config_tree import ConfigError

__all__ = ["HOST_PORT", "endpoint_host_port", "check_host_port", "picked_port"]

HOST_PORT = ("tcp", "tls", "udp", "quic", "ws")
"""The endpoint protocols of a ``HOST:PORT`` address."""

_PORT = re.compile(r"[0-9]{1,5}")  # ASCII digits only: str.isdigit and int take ٧٤٤٧, " 7447", "+7447", "7_447"


def _host(host: str) -> str:
    """``host`` without IPv6 brackets; ValueError saying why unless it is a host Zenoh could reach."""
    if not host or any(c.isspace() or not c.isprintable() for c in host):
        raise ValueError(f"the host {host!r} is empty or has a space or a control character")
    if host.startswith("[") and host.endswith("]"):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            raise ValueError(f"{host} is no IPv6 address") from None
        return host[1:-1]
    if any(c in host for c in ":[]"):  # tcp/127.0.0.1:7447:1, or an IPv6 address without its brackets
        raise ValueError(f"the host {host!r} has a ':' (an IPv6 address goes in brackets, e.g. tcp/[::1]:7447)")
    return host


def _host_port(endpoint: str) -> tuple[str, int]:
    """:func:`endpoint_host_port`, whose ValueError says what is wrong without naming the endpoint."""
    if "/" not in endpoint:
        raise ValueError("no proto/ part")
    address = endpoint.split("/", 1)[1].split("#")[0].split("?")[0]
    host, colon, port = address.rpartition(":")
    if not colon or not _PORT.fullmatch(port) or int(port) > 65535:
        raise ValueError(f"the port {port!r} is not a number 0-65535" if colon else "no :PORT")
    return _host(host), int(port)


def endpoint_host_port(endpoint: str) -> tuple[str, int]:
    """The host and port of a Zenoh endpoint: ``tcp/127.0.0.1:7447#...`` -> ``("127.0.0.1", 7447)``.

    Any protocol (``tcp/``, ``tls/``, ...); an IPv6 host (in brackets) loses its brackets; ``#`` and ``?`` parts
    are dropped.

    Raises:
        ValueError: No ``proto/`` part, a port that is not 0-65535 in ASCII digits, or a host that is empty, has a
            space or a control character, or has a ``:`` outside brackets.
    """
    try:
        return _host_port(endpoint)
    except ValueError as exc:
        raise ValueError(f"endpoint {endpoint!r} is not of the form proto/HOST:PORT: {exc}") from None


def check_host_port(option: str, endpoint: str, lowest: int) -> None:
    """Raise :class:`ConfigError` naming ``option`` unless ``endpoint`` is ``proto/HOST:PORT``, port ``lowest`` up."""
    try:
        _, port = _host_port(endpoint)
        why = "" if port >= lowest else f": port {port} is none to connect to"
    except ValueError as exc:
        why = f": {exc}"
    if why:
        raise ConfigError(f"{option}: endpoint {endpoint!r} is not of the form proto/HOST:PORT (a port "
                          f"{lowest}-65535){why}")


def picked_port(endpoint: str) -> bool:
    """Whether ``endpoint`` listens on a port picked at random (``:0``), which nothing can know to connect to."""
    try:
        return endpoint_host_port(endpoint)[1] == 0
    except ValueError:  # no port (a unix socket's path): a fixed address
        return False
