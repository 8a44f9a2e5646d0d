"""``foresight security``: certificates for mutual TLS, and the access control the sessions apply.

* ``foresight security init DIR [--hosts H1,H2] [--days N]``: a certificate authority and one
  certificate per role (``shared.security.acl.ROLES``) in DIR; run again, it re-issues the role certificates
  under the same authority and for the same hosts unless ``--hosts`` is given (rotation; ``--new-ca``
  replaces the authority).
* ``foresight security acl [--prefix P] [--zenoh-mode M]``: the generated ``access_control`` section (JSON), e.g. for
  a zenohd router's config file.
* ``foresight security check DIR [--role R]``: each certificate found (a machine holds its own roles'),
  its validity, its hosts and whether it verifies against the directory's CA.

Every service, ``foresight router`` and ``foresight demo`` take ``--security DIR`` (``[zenoh]
security_dir``, ``FORESIGHT_ZENOH_SECURITY_DIR``); docs/security.md has the threat model and a
two-machine deployment.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
from pathlib import Path

from shared.arguments import ArgumentParser
from shared.config import check_prefix
from shared.protocol import Keys
from shared.runtime import UserError, cli_errors, help_text
from shared.security.acl import ROLES, access_control, remote_roles
from shared.security.certificates import (
    CA_DAYS,
    certificate_hosts,
    check_host,
    check_private,
    fingerprint,
    init_security_dir,
    issued_hosts,
    load_authority,
    verify_role,
)

__all__ = ["main", "SUBCOMMANDS"]

SUBCOMMANDS: dict[str, str] = {
    "init": "a certificate authority and one certificate per role, for mutual TLS",
    "acl": "the access control generated from the wire contract (JSON)",
    "check": "each certificate's role, validity and signature against the CA",
}
"""The sub-commands of ``foresight security`` with one line each (``foresight --help`` lists them)."""


def _init(args: argparse.Namespace) -> int:
    if args.days < 1:
        raise UserError(f"--days must be >= 1, got {args.days}")
    kept = (args.dir / "ca.key").is_file() and not args.new_ca
    try:
        if args.hosts is None:  # rotation keeps the cell's hosts; a first init has none beyond loopback
            issued = issued_hosts(args.dir, ROLES) if args.dir.is_dir() else []  # --new-ca too: the cell's hosts
            hosts, dropped = [], []
            for h in issued:  # one issued before wildcards were refused (0.0.0.0) would stop every rotation
                try:
                    hosts.append(check_host(h))
                except ValueError:
                    dropped.append(h)
            if hosts:
                print(f"hosts kept from the certificates replaced: {', '.join(hosts)} (--hosts gives others)")
            if dropped:
                print(f"hosts dropped from the certificates replaced: {', '.join(dropped)} (no client connects to "
                      "them; --hosts gives the addresses clients connect to)")
        else:
            hosts = [h.strip() for h in args.hosts.split(",") if h.strip()]
        written = init_security_dir(args.dir, ROLES, hosts=hosts, days=args.days, force=args.new_ca)
    except (FileExistsError, ValueError) as exc:  # half an authority, a key that is not the certificate's, a host
        raise UserError(str(exc)) from None  # that is no host: nothing written
    for name, path in written.items():
        print(f"{path}{'  (private, 0600)' if name.endswith('.key') else ''}")
    print(f"roles: {', '.join(ROLES)}; hosts: localhost, 127.0.0.1{''.join(', ' + h for h in hosts)}; "
          f"valid {args.days} days. Give each machine ca.crt and only its own roles' .crt/.key; keep ca.key "
          "offline (docs/security.md)")
    if kept:  # a rotation: the authority, and what it signed, stay
        print("the authority was kept: the certificates it signed before stay valid until they expire; a key that "
              "may have leaked is locked out only by --new-ca")
    return 0


def _acl(args: argparse.Namespace) -> int:
    check_prefix(args.prefix, "--prefix")  # what every service refuses: a rule under it would grant another space
    print(json.dumps({"access_control": access_control(Keys(args.prefix), remote_roles(args.zenoh_mode))}, indent=2))
    return 0


def _check(args: argparse.Namespace) -> int:
    now = dt.datetime.now(dt.UTC)
    if not args.dir.is_dir():
        raise UserError(f"security directory {args.dir} does not exist")
    if args.role is not None and args.role not in ROLES:
        raise UserError(f"--role {args.role!r}: not one of {', '.join(ROLES)}")
    here = [r for r in ROLES if any((args.dir / f"{r}.{ext}").exists() for ext in ("crt", "key"))]
    roles = [args.role] if args.role else here  # a machine holds its own roles only (docs/security.md)
    if not roles:
        raise UserError(f"security directory {args.dir}: no role's certificate ({', '.join(ROLES)})")
    bad = 0
    try:  # the same on every machine of the cell: compare it there
        print(f"authority: {args.dir / 'ca.crt'}, SHA-256 {fingerprint(load_authority(args.dir / 'ca.crt'))}")
    except (OSError, ValueError) as exc:
        print(f"authority: {exc}")
        bad += 1
    for role in roles:
        try:
            cert = verify_role(args.dir, role, now=now)
        except (OSError, ValueError) as exc:  # a missing or unreadable file, or what verify_role refuses
            print(f"{role}: {exc}")
            bad += 1
            continue
        print(f"{role}: ok, valid until {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC, hosts "
              f"{', '.join(certificate_hosts(args.dir / f'{role}.crt'))}")
    if not args.role:
        print(f"not on this machine: {', '.join(r for r in ROLES if r not in here) or 'none'}")
    if (ca_key := args.dir / "ca.key").exists():  # it signs every role: only where the certificates are issued
        try:
            check_private(ca_key, "if others did read it, --new-ca")
            print(f"ca.key: here ({ca_key}); it signs certificates of every role: keep it only on the machine "
                  "that issues them, not on a service's")
        except (OSError, ValueError) as exc:
            print(f"ca.key: {exc}")
            bad += 1
    return 1 if bad else 0


def main(argv: list[str] | None = None, prog: str = "foresight security") -> int:
    """Run ``foresight security init|acl|check``; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=help_text(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="{" + ",".join(SUBCOMMANDS) + "}")
    p = sub.add_parser("init", help=SUBCOMMANDS["init"])
    p.add_argument("dir", type=Path, help="directory for ca.crt, ca.key and <role>.crt / <role>.key")
    p.add_argument("--hosts", default=None, help="comma-separated host names or addresses clients connect to "
                   "beyond loopback (e.g. the router's; not 0.0.0.0), written into every certificate (default: those "
                   "of the certificates being replaced, none at first)")
    p.add_argument("--days", type=int, default=365, help=f"validity of the role certificates (default: 365, at "
                   f"most the authority's {CA_DAYS})")
    p.add_argument("--new-ca", action="store_true", help="make a new authority even if DIR has one")
    p = sub.add_parser("acl", help=SUBCOMMANDS["acl"])
    p.add_argument("--prefix", default="foresight", help="key-expression prefix (default: foresight)")
    p.add_argument("--zenoh-mode", default="router", choices=("router", "peer", "client"),
                   help="the session's mode: a client's rules name its router only (default: router, every role)")
    p = sub.add_parser("check", help=SUBCOMMANDS["check"])
    p.add_argument("dir", type=Path, help="security directory")
    p.add_argument("--role", default=None, help="check this role only (default: every role with files in DIR)")
    args = parser.parse_args(argv)
    with cli_errors(f"{prog} {args.cmd}"):
        return {"init": _init, "acl": _acl, "check": _check}[args.cmd](args)
    return 2  # pragma: no cover


if __name__ == "__main__":
    sys.exit(main())
