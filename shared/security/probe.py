"""Why a mutual-TLS link does not come up: one handshake with the Python ``ssl`` module, its outcome in words.

Zenoh retries a refused TLS link in silence, and a client's warnings read the same whether the router is down,
its certificate is from another authority, its name is not the one connected to, or it refused this machine's
certificate (a review of a four-machine cell: all three said "a refused certificate ... looks like this"). One
handshake to the endpoint with the role's own files tells them apart; the warnings carry its line. This machine's
own files are checked first, as at start: a certificate that expired while the service ran was reported as the
other side's refusal (``sslv3 alert certificate expired``), every few seconds, without naming the file or when.
"""

from __future__ import annotations

import os
import socket
import ssl

from shared.config import endpoint_host_port

from .certificates import CertificateError, read_role, verify_role

__all__ = ["diagnose", "speaks_tls"]

_VERIFY = (("unable to get local issuer certificate", "not issued by this cell's authority (ca.crt)"),
           ("self-signed certificate", "not issued by this cell's authority (ca.crt)"),
           ("certificate has expired", "expired"),
           ("certificate is not yet valid", "not valid yet (check both machines' clocks)"),
           ("mismatch", "issued for other names (`foresight security init --hosts` names the router's)"))


def diagnose(endpoint: str, security_dir: str | os.PathLike[str], role: str, timeout: float = 2.0) -> str:
    """What one handshake with ``endpoint`` as ``role`` shows (a phrase, no trailing period).

    Args:
        endpoint: ``tls/HOST:PORT`` (or ``tcp/``: the same host and port).
        security_dir: The cell's directory (``ca.crt``, ``<role>.crt``, ``<role>.key``).
        role: The certificate presented.
        timeout: Seconds for the connection and the handshake.
    """
    try:
        host, port = endpoint_host_port(endpoint)
        verify_role(security_dir, role)  # this side first: ours expiring while the service ran was blamed on the router
        ca, cert, key = read_role(security_dir, role)
        context = ssl.create_default_context(cafile=str(ca))
        context.load_cert_chain(str(cert), str(key))
    except CertificateError as exc:  # this machine's file and what is wrong, e.g. planner.crt: expired at ... UTC
        return str(exc)
    except (ValueError, OSError, ssl.SSLError) as exc:
        return f"no handshake tried ({exc})"
    where = f"{host}:{port}"
    try:
        with socket.create_connection((host, port), timeout=timeout) as raw, \
                context.wrap_socket(raw, server_hostname=host) as tls:
            tls.settimeout(timeout)  # the whole timeout: a loaded machine's alert came after 0.5 s
            try:  # TLS 1.3: a server refuses the client's certificate after the handshake, with an alert
                tls.recv(1)
            except TimeoutError:
                return f"a handshake with {where} as {role} succeeds (the router accepts this certificate)"
            return f"{where} closed the link after the handshake"
    except ssl.SSLCertVerificationError as exc:
        message = exc.verify_message or str(exc)
        what = next((w for k, w in _VERIFY if k in message), message)
        return f"the certificate {where} presents is {what} ({message})"
    except ssl.SSLError as exc:
        reason = (exc.reason or str(exc)).lower().replace("_", " ")
        return f"{where} refused this machine's {role} certificate ({reason})"
    except ConnectionRefusedError:
        return f"nothing listens at {where} (connection refused)"
    except TimeoutError:
        return f"{where} does not answer within {timeout:g} s"
    except OSError as exc:
        return f"{where} cannot be reached ({exc.strerror or exc})"


def speaks_tls(endpoint: str, timeout: float = 2.0) -> bool:
    """Whether ``endpoint`` (``tcp/HOST:PORT``) answers a TLS handshake: a secure router, "not reachable" without TLS.

    The handshake verifies nothing and presents no certificate: a mutual-TLS router's refusal of that (an alert) says
    it speaks TLS as well as a finished handshake does; a plain Zenoh port answers no TLS record.
    """
    try:
        host, port = endpoint_host_port(endpoint)
    except ValueError:
        return False
    context = ssl.create_default_context()
    context.check_hostname = False
    context.verify_mode = ssl.CERT_NONE
    try:
        with socket.create_connection((host, port), timeout=timeout) as raw, \
                context.wrap_socket(raw, server_hostname=host):  # the handshake, within the socket's timeout
            return True
    except ssl.SSLError as exc:
        return "alert" in str(exc).lower()  # a TLS server's refusal; "wrong version number" etc. is no TLS
    except OSError:
        return False
