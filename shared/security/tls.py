"""A session's TLS settings from a security directory and a role; endpoints on TLS; the plain-TCP warning."""

from __future__ import annotations

import ipaddress
import os
from typing import TYPE_CHECKING, Any

from shared.loopback import is_loopback
from shared.protocol import Keys

from .acl import OBSERVER, access_control, remote_roles
from .certificates import certificate_hosts, read_role, verify_role

if TYPE_CHECKING:
    from shared.config import ZenohConfig

__all__ = ["tls_settings", "secure_endpoints", "insecure_listen_warning", "listen_warning", "security_settings"]


def tls_settings(security_dir: str | os.PathLike[str], role: str) -> dict[str, Any]:
    """Zenoh's ``transport/link/tls`` section: mutual TLS with the role's certificate, names verified.

    The certificate is checked first (:func:`verify_role`), so a session with an expired, foreign or mismatched
    one fails at once with one line naming it, rather than retrying a link the other side refuses. A link is
    closed when its certificate expires (Zenoh keeps it open otherwise).

    Raises:
        FileNotFoundError: If the CA or the role's certificate or key is missing (naming it).
        CertificateError: If the certificate or key cannot be used now (naming what is wrong).
    """
    verify_role(security_dir, role)
    ca, cert, key = read_role(security_dir, role)
    return {
        "close_link_on_expiration": True,
        "root_ca_certificate": str(ca),
        "enable_mtls": True,
        "listen_private_key": str(key),
        "listen_certificate": str(cert),
        "connect_private_key": str(key),
        "connect_certificate": str(cert),
        "verify_name_on_connect": True,
    }


def secure_endpoints(endpoints: list[str]) -> list[str]:
    """``tcp/HOST:PORT`` -> ``tls/HOST:PORT``, ``tls/`` kept: no plain-text link when secure.

    Raises:
        ConfigError: An endpoint of another protocol (``udp/``, ``ws/``, ``unixsock-stream/`` ...), which would
            carry plain text beside the TLS links (access control would cut its peers off, silently).
    """
    from shared.config import ConfigError

    plain = [ep for ep in endpoints if not ep.startswith(("tcp/", "tls/"))]
    if plain:
        raise ConfigError(f"zenoh endpoints: with security every link is TLS (tcp/HOST:PORT becomes tls/); "
                          f"{', '.join(plain)} would not be")
    return [f"tls/{ep[4:]}" if ep.startswith("tcp/") else ep for ep in endpoints]


def _host(endpoint: str) -> str:
    address = endpoint.split("/", 1)[1].split("#")[0]
    host = address.rsplit(":", 1)[0] if ":" in address else address
    return host.strip("[]")


def insecure_listen_warning(listen: list[str]) -> str:
    """One warning line when a session without security listens beyond loopback ("" when it does not)."""
    exposed = []
    for ep in listen:
        if not is_loopback(_host(ep)):
            exposed.append(ep)
    if not exposed:
        return ""
    return (f"listening on {', '.join(exposed)} without security: anyone who reaches it may read and write every "
            "key; use --security DIR (foresight security init, docs/security.md)")


def _canonical(host: str) -> str:
    """A host as a certificate's names compare: an address in its one written form, a DNS name in lower case."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return host.lower()


def names_host(named: set[str], host: str) -> bool:
    """Whether a certificate naming ``named`` (canonical, :func:`_canonical`) names ``host``, as a peer checks it.

    A wildcard ``*.robot.lan`` names one label more (``a.robot.lan``, not ``robot.lan`` nor ``a.b.robot.lan``) and
    never an address (RFC 6125, 6.4.3).
    """
    host = _canonical(host)
    if host in named:
        return True
    label, _, rest = host.partition(".")
    return bool(label and rest and f"*.{rest}" in named and not _is_address(host))


def _is_address(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def listen_warning(cfg: ZenohConfig) -> str:
    """The one warning a session's listen endpoints call for, or "".

    Without security: listening beyond loopback (:func:`insecure_listen_warning`). With it: listening on a host
    its certificate does not name, which every peer connecting there refuses (``verify_name_on_connect``).
    """
    if not cfg.security_dir:
        return insecure_listen_warning(list(cfg.listen))
    role = cfg.role or OBSERVER
    _, cert, _ = read_role(cfg.security_dir, role)
    named = {_canonical(h) for h in certificate_hosts(cert)}
    unnamed = [ep for ep in secure_endpoints(list(cfg.listen))
               if (host := _canonical(_host(ep))) not in ("0.0.0.0", "::", "") and not names_host(named, host)]
    if not unnamed:
        return ""
    return (f"listening on {', '.join(unnamed)}, which {role}.crt does not name (it names {', '.join(sorted(named))}): "
            "a peer connecting there refuses the link; make the certificates with --hosts naming it "
            "(foresight security init, docs/security.md)")


def security_settings(cfg: ZenohConfig) -> tuple[list[str], list[str], dict[str, Any]]:
    """A session's endpoints and the Zenoh config entries its security asks for.

    With ``cfg.security_dir``: endpoints on TLS, ``transport/link/tls`` (mutual TLS with the role's
    certificate) and ``access_control`` (generated from the wire contract; in client mode for the router only, the
    one remote a client has). Without: the endpoints as
    given and no entries (:func:`insecure_listen_warning` says, once per session, when they listen beyond
    loopback).

    Returns:
        ``(listen, connect, {config path: value})``.
    """
    listen, connect = list(cfg.listen), list(cfg.connect)
    if not cfg.security_dir:
        return listen, connect, {}
    return secure_endpoints(listen), secure_endpoints(connect), {
        "transport/link/tls": tls_settings(cfg.security_dir, cfg.role or OBSERVER),
        "access_control": access_control(Keys(cfg.prefix), remote_roles(cfg.mode)),
    }
