"""``foresight security``: certificates for mutual TLS, and the access control the sessions apply.

* ``foresight security init DIR [--hosts H1,H2] [--days N]``: a certificate authority and one
  certificate per role (router, replayer, predictor, planner, executor, observer) in DIR; run again,
  it re-issues the role certificates under the same authority (rotation; ``--new-ca`` replaces it).
* ``foresight security acl [--prefix P]``: the generated ``access_control`` section (JSON), e.g. for
  a zenohd router's config file.
* ``foresight security check DIR``: each certificate's role, validity and whether it verifies
  against the directory's CA.

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

from shared.protocol import Keys
from shared.runtime import UserError, cli_errors, help_text
from shared.security.acl import ROLES, access_control
from shared.security.certificates import init_security_dir, verify_role

__all__ = ["main", "SUBCOMMANDS"]

SUBCOMMANDS: dict[str, str] = {
    "init": "a certificate authority and one certificate per role, for mutual TLS",
    "acl": "the access control generated from the wire contract (JSON)",
    "check": "each certificate's role, validity and signature against the CA",
}
"""The sub-commands of ``foresight security`` with one line each (``foresight --help`` lists them)."""


def _init(args: argparse.Namespace) -> int:
    hosts = [h.strip() for h in args.hosts.split(",") if h.strip()]
    if args.days < 1:
        raise UserError(f"--days must be >= 1, got {args.days}")
    try:
        written = init_security_dir(args.dir, ROLES, hosts=hosts, days=args.days, force=args.new_ca)
    except (FileExistsError, ValueError) as exc:  # half an authority, a key that is not the certificate's, a host
        raise UserError(str(exc)) from None  # that is no host: nothing written
    for name, path in written.items():
        print(f"{path}{'  (private, 0600)' if name.endswith('.key') else ''}")
    print(f"roles: {', '.join(ROLES)}; hosts: localhost, 127.0.0.1{''.join(', ' + h for h in hosts)}; "
          f"valid {args.days} days. Give each machine ca.crt and only its own roles' .crt/.key; keep ca.key "
          "offline (docs/security.md)")
    return 0


def _acl(args: argparse.Namespace) -> int:
    print(json.dumps({"access_control": access_control(Keys(args.prefix))}, indent=2))
    return 0


def _check(args: argparse.Namespace) -> int:
    now = dt.datetime.now(dt.UTC)
    bad = 0
    for role in ROLES:
        try:
            cert = verify_role(args.dir, role, now=now)
        except (FileNotFoundError, ValueError) as exc:
            print(f"{role}: {exc}")
            bad += 1
            continue
        print(f"{role}: ok, valid until {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC")
    return 1 if bad else 0


def main(argv: list[str] | None = None, prog: str = "foresight security") -> int:
    """Run ``foresight security init|acl|check``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description=help_text(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="{" + ",".join(SUBCOMMANDS) + "}")
    p = sub.add_parser("init", help=SUBCOMMANDS["init"])
    p.add_argument("dir", type=Path, help="directory for ca.crt, ca.key and <role>.crt / <role>.key")
    p.add_argument("--hosts", default="", help="comma-separated host names or addresses the sessions listen on "
                   "beyond loopback (e.g. the router's), written into every certificate")
    p.add_argument("--days", type=int, default=365, help="validity of the role certificates (default: 365)")
    p.add_argument("--new-ca", action="store_true", help="make a new authority even if DIR has one")
    p = sub.add_parser("acl", help=SUBCOMMANDS["acl"])
    p.add_argument("--prefix", default="foresight", help="key-expression prefix (default: foresight)")
    p = sub.add_parser("check", help=SUBCOMMANDS["check"])
    p.add_argument("dir", type=Path, help="security directory")
    args = parser.parse_args(argv)
    with cli_errors(f"{prog} {args.cmd}"):
        return {"init": _init, "acl": _acl, "check": _check}[args.cmd](args)
    return 2  # pragma: no cover


if __name__ == "__main__":
    sys.exit(main())
