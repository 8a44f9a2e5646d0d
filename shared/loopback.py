"""Whether an address stays on this machine: the one test behind every "beyond loopback" warning.

Zenoh's listen endpoints without security (:func:`shared.security.tls.insecure_listen_warning`) and the live
view's WebSocket (:class:`shared.foxglove.live.LiveServer`, which has no authentication) warn when they serve
a host for which :func:`is_loopback` is false.
"""

from __future__ import annotations

import ipaddress

__all__ = ["is_loopback"]


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address, an IPv6 one possibly in brackets, or a name) is reachable from this machine only.

    Only loopback addresses and ``localhost`` are; any other name may resolve beyond it.
    """
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return host.lower() == "localhost"
