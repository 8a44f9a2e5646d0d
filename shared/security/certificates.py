"""Certificates for mutual TLS between Foresight's sessions: one authority, one certificate per role.

:func:`init_security_dir` writes ``ca.crt`` (the authority; its key ``ca.key`` stays beside it for
issuing and rotating) and, for each role of :data:`shared.security.acl.ROLES`, ``<role>.crt`` and
``<role>.key``: PEM, keys readable by their owner only (0600), the role as the certificate's common
name (Zenoh's access control matches subjects by it), and subject alternative names for the hosts
the certificate's holder serves (``--hosts``: the router's; every certificate names ``localhost`` and
``127.0.0.1`` so that loopback runs verify; ``--hosts`` adds names to every certificate, since a peer
listens as well as the router). Keys are ECDSA P-256; certificates are valid for
``days`` days. Everything with the ``cryptography`` library, nothing shelled out.
"""

from __future__ import annotations

import datetime as dt
import errno
import ipaddress
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.asymmetric.types import PrivateKeyTypes
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from ..atomic_file import atomic_write
from .files import CertificateError, check_directory, check_private, check_readable, read_role

__all__ = ["Issued", "CertificateError", "make_authority", "issue", "init_security_dir", "read_role", "verify_role",
           "check_host", "check_directory", "issued_hosts", "certificate_hosts", "load_authority", "fingerprint",
           "LOOPBACK_HOSTS", "CA_DAYS", "check_private", "check_readable"]

LOOPBACK_HOSTS = ("localhost", "127.0.0.1")
"""Names every certificate carries, so that a run on one machine verifies."""
CA_DAYS = 3650
"""Validity of a new authority (days); no role certificate outlives it."""


@dataclass(frozen=True)
class Issued:
    """A certificate and its private key (PEM bytes)."""

    cert_pem: bytes
    key_pem: bytes

    @property
    def certificate(self) -> x509.Certificate:
        """The parsed certificate."""
        return x509.load_pem_x509_certificate(self.cert_pem)


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


def check_host(host: str) -> str:
    """``host`` if it is an IP address or a DNS name a certificate can carry, else a ``ValueError`` saying why.

    An address is written bare (``::1``, not ``[::1]``) and a name has no port: a certificate names hosts,
    and a name it does not match exactly is refused by the peer at the first connection, far from here. The
    unspecified addresses (``0.0.0.0``, ``::``: what ``--listen`` binds to) and multicast groups are refused:
    no client connects to them, so the certificate would match none of its connections.
    A DNS name is dot-separated labels of letters, digits and inner hyphens (RFC 1123), the first may be
    ``*`` (a wildcard) when others follow, and the last is not all digits (``192.168.1.300`` is a mistyped
    address, not a name); a trailing dot (the DNS root) is dropped, since peers never match it.
    """
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        pass
    else:
        if getattr(address, "scope_id", None):  # fe80::1%eth0: the certificate would name fe80::1, no word said
            raise ValueError(f"host {host!r}: a certificate names an address without its scope (give "
                             f"{host.split('%')[0]!r}; the scope is the endpoint's)")
        if address.is_unspecified or address.is_multicast:  # 0.0.0.0 copied from --listen: refused at connect
            what = "the listen wildcard" if address.is_unspecified else "a multicast group"
            raise ValueError(f"host {host!r} is {what}, which no client connects to: give the address clients "
                             "connect to (e.g. 192.168.1.10 or robot.local)")
        return str(address)
    if host.startswith("[") and "]" in host:
        raise ValueError(f"host {host!r}: write an IPv6 address without brackets or port "
                         f"({host[1:host.index(']')]!r})")
    if host.count(":") == 1 and host.rsplit(":", 1)[1].isdigit():
        raise ValueError(f"host {host!r}: a certificate names hosts, not ports (give {host.rsplit(':', 1)[0]!r})")
    name = host[:-1] if host.endswith(".") else host
    labels = name.split(".")
    if len(name) > 253 or not all(_LABEL.fullmatch(lab) or (i == 0 and lab == "*" and len(labels) > 1)
                                  for i, lab in enumerate(labels)):
        raise ValueError(f"host {host!r} is neither an IP address nor a DNS name (letters, digits and inner hyphens "
                         "between dots, e.g. robot.local; a wildcard only as *.robot.local)")
    if labels[-1].isdigit():
        raise ValueError(f"host {host!r} is no IP address (four numbers 0-255, e.g. 192.168.1.10) and a DNS name "
                         "does not end in a number")
    return name


def _san(hosts: Iterable[str]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    for host in dict.fromkeys(check_host(h) for h in hosts):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(names)


def make_authority(name: str = "Foresight CA", days: int = CA_DAYS,
                   now: dt.datetime | None = None) -> Issued:
    """A self-signed certificate authority (may sign certificates, not be a TLS peer)."""
    now = now or dt.datetime.now(dt.UTC)
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name),
                         x509.NameAttribute(NameOID.ORGANIZATION_NAME, "Foresight")])
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5)).not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
            .sign(key, hashes.SHA256()))
    return Issued(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


def issue(authority: Issued, role: str, hosts: Sequence[str] = (), days: int = 365,
          now: dt.datetime | None = None, not_after: dt.datetime | None = None) -> Issued:
    """A certificate for ``role`` (its common name), signed by ``authority``, for client and server use.

    Args:
        authority: The CA (certificate and key).
        role: Common name, e.g. ``planner``.
        hosts: DNS names or IP addresses the holder serves, beside :data:`LOOPBACK_HOSTS`.
        days: Validity from ``now``; never past the authority's end (with its ``days``, a role certificate ended
            milliseconds after the authority that signed it).
        now: Issue time (default: now).
        not_after: End of validity, overriding ``days`` (tests make expired certificates with it).
    """
    now = now or dt.datetime.now(dt.UTC)
    ca_cert = authority.certificate
    ca_key = serialization.load_pem_private_key(authority.key_pem, password=None)
    if not isinstance(ca_key, ec.EllipticCurvePrivateKey):
        raise ValueError("the authority's key is not an EC key")
    key = ec.generate_private_key(ec.SECP256R1())
    end = min(not_after or now + dt.timedelta(days=days), ca_cert.not_valid_after_utc)
    start = min(now - dt.timedelta(minutes=5), end - dt.timedelta(minutes=10))
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, role),
                                     x509.NameAttribute(NameOID.ORGANIZATION_NAME, "Foresight")]))
            .issuer_name(ca_cert.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(end)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_encipherment=False, key_cert_sign=False,
                                         crl_sign=False, content_commitment=False, data_encipherment=False,
                                         key_agreement=True, encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .add_extension(_san([*hosts, *LOOPBACK_HOSTS]), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256()))
    return Issued(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


def _write(path: Path, data: bytes, private: bool) -> None:
    """Write ``data`` to ``path`` whole and on disk (flushed, renamed), 0600 if ``private`` before a byte is written."""
    with atomic_write(path, mode=0o600 if private else 0o644, fsync=True) as f:  # a crash: no empty ca.key
        f.write(data)


def _load_cert(path: Path) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError as exc:  # cryptography's text names no file
        raise CertificateError(f"{path}: not a PEM certificate ({str(exc).splitlines()[0][:80]})") from None


def load_authority(path: Path) -> x509.Certificate:
    """The cell's one authority from ``ca.crt``.

    Raises:
        CertificateError: The file holds no certificate, more than one (Zenoh trusts each: a second is a second
            authority whose certificates every session would accept), or one that is no certificate authority.
    """
    pems = re.findall(rb"-----BEGIN CERTIFICATE-----", path.read_bytes())
    if len(pems) > 1:
        raise CertificateError(f"{path}: holds {len(pems)} certificates; a cell's ca.crt holds its one authority "
                               "(every certificate in it would be trusted: someone added one?)")
    ca = _load_cert(path)
    try:
        is_ca = ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        is_ca = False
    if not is_ca:
        raise CertificateError(f"{path}: not a certificate authority (a role's certificate copied over ca.crt?)")
    return ca


def fingerprint(cert: x509.Certificate) -> str:
    """SHA-256 fingerprint, ``AB:CD:...``: compare the authority's on every machine of a cell."""
    return cert.fingerprint(hashes.SHA256()).hex(":").upper()


def _validity(cert: x509.Certificate, name: str, now: dt.datetime) -> None:
    """Refuse ``cert`` outside its validity, saying which end and this machine's clock (a clock off, say)."""
    clock = f"this machine's clock: {now:%Y-%m-%d %H:%M} UTC"
    if now < cert.not_valid_before_utc:
        raise CertificateError(f"{name}: not valid before {cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC ({clock}; "
                               "is it behind?)")
    if now > cert.not_valid_after_utc:
        raise CertificateError(f"{name}: expired at {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC ({clock}); "
                               "issue new certificates: foresight security init DIR (docs/security.md, rotation)")


def issued_hosts(directory: str | os.PathLike[str], roles: Sequence[str]) -> list[str]:
    """The hosts (beyond loopback) the directory's certificates name: the router's, else the first role's found.

    ``foresight security init`` run again without ``--hosts`` keeps them (rotation must not drop the cell's hosts).
    """
    d = Path(directory)
    for role in ("router", *roles):
        if (d / f"{role}.crt").is_file():
            return [h for h in certificate_hosts(d / f"{role}.crt") if h not in LOOPBACK_HOSTS]
    return []


def certificate_hosts(path: str | os.PathLike[str]) -> list[str]:
    """The DNS names and IP addresses a certificate names (its subject alternative names), as text.

    Raises:
        CertificateError: The file is not a PEM certificate.
    """
    cert = _load_cert(Path(path))
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return []
    return [str(n.value) for n in san]


def init_security_dir(directory: str | os.PathLike[str], roles: Sequence[str], hosts: Sequence[str] = (),
                      days: int = 365, force: bool = False) -> dict[str, Path]:
    """Write a CA and one certificate per role into ``directory``; returns the files written by name.

    Args:
        directory: Where (created if missing).
        roles: Common names, one certificate each (every one gets ``hosts`` as alternative names).
        hosts: Host names or addresses the sessions listen on beyond loopback (beside localhost), in every
            certificate: the router's in client mode, each peer's too in peer mode.
        days: Validity of the role certificates (the CA: ten years).
        force: Replace an existing authority (without it an existing ``ca.crt`` and ``ca.key`` are reused, so
            that running it again re-issues the role certificates under the same CA: rotation).

    Raises:
        FileExistsError: Without ``force``, the directory holds one of ``ca.crt`` and ``ca.key`` but not the
            other (a cell machine holds only ``ca.crt``: a new authority there would lock it out of its cell), or
            a ``ca.key`` that does not match ``ca.crt``.
        ValueError: A host that is neither an IP address nor a DNS name (:func:`check_host`), ``days`` past the
            authority's end, or a directory others may write (:func:`check_directory`); nothing written.
    """
    hosts = [check_host(h) for h in hosts]
    now = dt.datetime.now(dt.UTC)  # one time for the authority and every role: --days N of each ends together
    d = Path(directory)
    d.mkdir(mode=0o700, parents=True, exist_ok=True)  # 0700 whatever the umask (002 made it 775, then refused)
    check_directory(d)
    if not os.access(d, os.W_OK | os.X_OK):  # one Docker made, root's: the error named a temporary file of ours
        raise PermissionError(errno.EACCES, f"cannot write into it (owned by uid {d.stat().st_uid}; "
                              "chown it or remove it)", str(d))
    ca_crt, ca_key = d / "ca.crt", d / "ca.key"
    if not force and ca_crt.is_file() != ca_key.is_file():
        have, lacks = (ca_crt, ca_key) if ca_crt.is_file() else (ca_key, ca_crt)
        raise FileExistsError(f"security directory {d} holds {have.name} without {lacks.name}: certificates are "
                              f"issued where both are (copy the role files from there), or --new-ca makes a new "
                              "authority, which every machine of the cell must then get")
    if ca_crt.is_file() and ca_key.is_file() and not force:
        check_private(ca_key, "anyone who read it can issue certificates of any role: if others did, --new-ca")
        authority = Issued(ca_crt.read_bytes(), ca_key.read_bytes())
        try:
            key = serialization.load_pem_private_key(authority.key_pem, password=None)
        except (ValueError, TypeError) as exc:
            raise CertificateError(f"{ca_key}: not a PEM key readable without a password "
                                   f"({str(exc).splitlines()[0][:80]})") from None
        ca = load_authority(ca_crt)  # one authority, a CA: a second one added would be handed out with it
        if not _same_key(ca, key):
            raise FileExistsError(f"security directory {d}: ca.key is not the key of ca.crt")
        _validity(ca, "ca.crt (the authority)", now)
        left = ca.not_valid_after_utc - now
        if dt.timedelta(days=days) > left:
            raise CertificateError(f"--days {days}: the authority (ca.crt) ends on {ca.not_valid_after_utc:%Y-%m-%d}, "
                                   f"in {left.days} days; a certificate cannot outlive it (--new-ca makes a new one)")
    elif days > CA_DAYS:
        raise CertificateError(f"--days {days}: at most {CA_DAYS}, the validity of a new authority")
    else:
        authority = make_authority(now=now)
        _write(ca_crt, authority.cert_pem, private=False)
        _write(ca_key, authority.key_pem, private=True)
    written = {"ca.crt": ca_crt, "ca.key": ca_key}
    for role in roles:
        issued = issue(authority, role, hosts, days=days, now=now)
        _write(d / f"{role}.crt", issued.cert_pem, private=False)
        _write(d / f"{role}.key", issued.key_pem, private=True)
        written[f"{role}.crt"] = d / f"{role}.crt"
        written[f"{role}.key"] = d / f"{role}.key"
    fd = os.open(d, os.O_RDONLY)  # the renames on disk too
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    return written


def verify_role(directory: str | os.PathLike[str], role: str, now: dt.datetime | None = None) -> x509.Certificate:
    """Check ``<role>.crt``: signed by the directory's CA, common name ``role``, valid at ``now``; returns it.

    Raises:
        FileNotFoundError: A file is missing.
        CertificateError: Naming what is wrong (a file that is not PEM, signature, common name, validity, a key
            that is not the certificate's, that others may read or that cannot be read without a password, a
            directory others may write).
    """
    ca_path, cert_path, key_path = read_role(directory, role)
    check_directory(directory, ("ca.crt", f"{role}.crt", f"{role}.key"))
    for path in (ca_path, cert_path, key_path):
        check_readable(path)
    ca, cert = load_authority(ca_path), _load_cert(cert_path)
    check_private(key_path)  # a key others can read is no longer this role's alone
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature) as exc:
        raise CertificateError(f"{cert_path.name} is not signed by {ca_path.name} ({type(exc).__name__})") from None
    names = [a.value for a in cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)]
    if names != [role]:
        raise CertificateError(f"{cert_path.name}: common name {names} is not [{role!r}]")
    now = now or dt.datetime.now(dt.UTC)
    _validity(ca, f"{ca_path.name} (the authority)", now)  # an expired one was blamed on the peer's certificate
    _validity(cert, cert_path.name, now)
    try:
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except (ValueError, TypeError) as exc:  # TypeError: the key is encrypted (a session cannot ask for a password)
        raise CertificateError(f"{key_path.name}: cannot be read without a password or is not a key "
                               f"({str(exc).splitlines()[0][:80]})") from None
    if not _same_key(cert, key):
        raise CertificateError(f"{key_path.name} does not belong to {cert_path.name}")
    return cert


def _same_key(cert: x509.Certificate, key: PrivateKeyTypes) -> bool:
    """Whether ``key`` is the private key of ``cert`` (their public keys are the same)."""
    der, spki = serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    return bool(key.public_key().public_bytes(der, spki) == cert.public_key().public_bytes(der, spki))
