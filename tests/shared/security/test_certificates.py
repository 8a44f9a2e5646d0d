"""`foresight security init`: a CA and one certificate per role that verify against it and carry their role."""

from __future__ import annotations

import datetime as dt
import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import NameOID

from shared.security.acl import ROLES
from shared.security.certificates import init_security_dir, issue, make_authority, read_role, verify_role
from tools.security import main


def test_init_writes_a_ca_and_a_certificate_per_role(tmp_path: Path) -> None:
    assert main(["init", str(tmp_path / "sec"), "--hosts", "robot.local,10.0.0.5"]) == 0
    d = tmp_path / "sec"
    for role in ROLES:
        cert = verify_role(d, role)
        assert [a.value for a in cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)] == [role]
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert {"localhost", "robot.local"} <= set(san.get_values_for_type(x509.DNSName))
        assert stat.S_IMODE((d / f"{role}.key").stat().st_mode) == 0o600
        assert stat.S_IMODE((d / f"{role}.crt").stat().st_mode) == 0o644
    assert stat.S_IMODE((d / "ca.key").stat().st_mode) == 0o600
    assert main(["check", str(d)]) == 0


def test_running_again_rotates_under_the_same_authority(tmp_path: Path) -> None:
    d = tmp_path / "sec"
    init_security_dir(d, ["planner"])
    ca, first = (d / "ca.crt").read_bytes(), (d / "planner.crt").read_bytes()
    init_security_dir(d, ["planner"])
    assert (d / "ca.crt").read_bytes() == ca and (d / "planner.crt").read_bytes() != first
    verify_role(d, "planner")
    init_security_dir(d, ["planner"], force=True)
    assert (d / "ca.crt").read_bytes() != ca


def test_check_names_what_is_wrong(tmp_path: Path) -> None:
    d, other = tmp_path / "sec", tmp_path / "other"
    init_security_dir(d, ["planner", "executor"])
    init_security_dir(other, ["planner"])
    (d / "executor.crt").write_bytes((other / "planner.crt").read_bytes())  # another CA, another role
    with pytest.raises(ValueError, match="not signed by ca.crt"):
        verify_role(d, "executor")
    authority = make_authority()
    expired = issue(authority, "planner", not_after=dt.datetime.now(dt.UTC) - dt.timedelta(days=1))
    (other / "ca.crt").write_bytes(authority.cert_pem)
    (other / "planner.crt").write_bytes(expired.cert_pem)
    (other / "planner.key").write_bytes(expired.key_pem)
    with pytest.raises(ValueError, match="not valid now"):
        verify_role(other, "planner")
    with pytest.raises(FileNotFoundError, match="observer.crt is missing .*foresight security init"):
        read_role(d, "observer")
