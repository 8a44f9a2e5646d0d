"""`foresight security init`: a CA and one certificate per role that verify against it and carry their role."""

from __future__ import annotations

import datetime as dt
import os
import re
import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import NameOID

from shared.security.acl import ROLES
from shared.security.certificates import (
    CertificateError,
    init_security_dir,
    issue,
    issued_hosts,
    make_authority,
    read_role,
    verify_role,
)
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
    with pytest.raises(ValueError, match=r"planner.crt: expired at .* UTC \(this machine's clock: .* UTC\)"):
        verify_role(other, "planner")
    early = issue(authority, "planner", now=dt.datetime.now(dt.UTC) + dt.timedelta(minutes=20))  # starts in 15
    (other / "planner.crt").write_bytes(early.cert_pem)
    (other / "planner.key").write_bytes(early.key_pem)
    with pytest.raises(ValueError, match=r"planner.crt: not valid before .* UTC \(this machine's clock: .*is it "
                                         r"behind\?\)"):  # a robot whose clock is behind read 'not valid now'
        verify_role(other, "planner")
    with pytest.raises(FileNotFoundError, match="observer.crt is missing .*foresight security init"):
        read_role(d, "observer")


def test_a_cell_machine_without_the_ca_key_is_never_given_a_new_authority(tmp_path: Path) -> None:
    admin, cell = tmp_path / "admin", tmp_path / "cell"
    init_security_dir(admin, ["planner"])
    cell.mkdir()
    (cell / "ca.crt").write_bytes((admin / "ca.crt").read_bytes())  # ca.key stays offline, as docs/security.md says
    with pytest.raises(FileExistsError, match="holds ca.crt without ca.key"):
        init_security_dir(cell, ["tracker"])
    assert (cell / "ca.crt").read_bytes() == (admin / "ca.crt").read_bytes() and not (cell / "ca.key").exists()
    with pytest.raises(SystemExit) as stopped:  # the command: one line, status 2
        main(["init", str(cell)])
    assert stopped.value.code == 2 and not (cell / "ca.key").exists()
    other = tmp_path / "other"
    init_security_dir(other, [])
    (admin / "ca.key").write_bytes((other / "ca.key").read_bytes())  # a key of another authority
    with pytest.raises(FileExistsError, match="ca.key is not the key of ca.crt"):
        init_security_dir(admin, ["planner"])


def test_a_key_file_that_was_readable_is_replaced_private(tmp_path: Path) -> None:
    init_security_dir(tmp_path, ["planner"])
    key = tmp_path / "planner.key"
    key.chmod(0o644)
    old = key.read_bytes()
    init_security_dir(tmp_path, ["planner"])  # rotation
    assert stat.S_IMODE(key.stat().st_mode) == 0o600 and key.read_bytes() != old
    assert verify_role(tmp_path, "planner") and not list(tmp_path.glob(".*.tmp"))


@pytest.mark.parametrize(("host", "match"), [
    ("[::1]", r"without brackets or port \('::1'\)"),
    ("[fe80::1]:7447", r"without brackets or port \('fe80::1'\)"),
    ("robot.local:7447", r"names hosts, not ports \(give 'robot.local'\)"),
    ("robot local", "neither an IP address nor a DNS name"),
    ("-robot.local", "neither an IP address nor a DNS name"),
    ("robot..local", "neither an IP address nor a DNS name"),
    ("a." * 127 + "b", "neither an IP address nor a DNS name"),
    ("*", "a wildcard only as"),  # peers (rustls) never match these two
    ("192.168.1.300", "no IP address"),
    ("10.0.0", "no IP address"),
    ("fe80::1%eth0", r"names an address without its scope \(give 'fe80::1'"),  # it named fe80::1, no word said
    ("0.0.0.0", "the listen wildcard, which no client connects to: give the address clients connect to"),
    ("::", "the listen wildcard"),  # copied from --listen: accepted, then every client refused the router
    ("224.0.0.224", "a multicast group"),
    ("ff02::1", "a multicast group"),
])
def test_a_host_a_certificate_cannot_name_is_refused_before_anything_is_written(tmp_path: Path, host: str,
                                                                                 match: str, capsys) -> None:
    d = tmp_path / "sec"
    with pytest.raises(ValueError, match=match):
        init_security_dir(d, ["planner"], hosts=[host])
    assert not d.exists() or not any(d.iterdir())
    with pytest.raises(SystemExit) as stopped:  # the command: one line, status 2
        main(["init", str(d), "--hosts", f"robot.local,{host}"])
    assert stopped.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and host in err[0], err
    assert not d.exists() or not any(d.iterdir())


def test_addresses_and_names_a_certificate_can_carry(tmp_path: Path) -> None:
    hosts = ["::1", "fe80::1", "10.0.0.5", "robot.local", "cell.local.", "*.cell.local", "r2-d2"]
    init_security_dir(tmp_path, ["router"], hosts=hosts)
    san = verify_role(tmp_path, "router").extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert set(san.get_values_for_type(x509.DNSName)) == {"robot.local", "cell.local", "*.cell.local", "r2-d2",
                                                          "localhost"}  # the DNS root's dot dropped: peers match
    assert {str(a) for a in san.get_values_for_type(x509.IPAddress)} == {"::1", "fe80::1", "10.0.0.5", "127.0.0.1"}


def test_rotation_without_hosts_keeps_the_hosts_of_the_certificates_it_replaces(tmp_path: Path, capsys) -> None:
    """Run again as the docs say, init re-issued the router's certificate for loopback only: the cell locked out."""
    assert main(["init", str(tmp_path), "--hosts", "robot.local,192.168.1.10"]) == 0
    capsys.readouterr()
    assert main(["init", str(tmp_path)]) == 0
    assert "hosts kept from the certificates replaced: robot.local, 192.168.1.10" in capsys.readouterr().out
    assert issued_hosts(tmp_path, ROLES) == ["robot.local", "192.168.1.10"]
    assert main(["init", str(tmp_path), "--hosts", "cell.local"]) == 0  # given: they replace the old ones
    assert issued_hosts(tmp_path, ROLES) == ["cell.local"]
    old_ca = (tmp_path / "ca.crt").read_bytes()
    capsys.readouterr()
    assert main(["init", str(tmp_path), "--new-ca"]) == 0  # a leaked ca.key's answer dropped every host
    assert (tmp_path / "ca.crt").read_bytes() != old_ca and issued_hosts(tmp_path, ROLES) == ["cell.local"]
    assert "hosts kept from the certificates replaced: cell.local" in capsys.readouterr().out
    assert main(["check", str(tmp_path)]) == 0
    assert re.search(r"^authority: .*ca.crt, SHA-256 ([0-9A-F]{2}:){31}[0-9A-F]{2}$", capsys.readouterr().out, re.M)


def test_rotation_drops_a_listen_wildcard_its_old_certificates_named(tmp_path: Path, monkeypatch, capsys) -> None:
    """Certificates issued before wildcards were refused may name 0.0.0.0: init without --hosts re-read them and
    stopped at check_host, so the cell could not rotate until someone passed --hosts."""
    import shared.security.certificates as certificates

    real = certificates.check_host
    monkeypatch.setattr(certificates, "check_host", lambda h: h if h == "0.0.0.0" else real(h))  # the old rule
    init_security_dir(tmp_path, ROLES, hosts=["0.0.0.0", "robot.local"])
    monkeypatch.undo()
    assert issued_hosts(tmp_path, ROLES) == ["0.0.0.0", "robot.local"]
    assert main(["init", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "hosts kept from the certificates replaced: robot.local" in out
    assert "hosts dropped from the certificates replaced: 0.0.0.0 (no client connects to them" in out
    assert issued_hosts(tmp_path, ROLES) == ["robot.local"]


def test_a_directory_others_may_write_is_refused_and_no_planted_link_is_followed(tmp_path: Path) -> None:
    d = tmp_path / "sec"
    init_security_dir(d, ["planner"])
    d.chmod(0o777)  # anyone could put an authority of their own in ca.crt
    with pytest.raises(CertificateError, match=r"writable by others \(mode 777\).*chmod go-w"):
        verify_role(d, "planner")
    with pytest.raises(CertificateError, match="writable by others"):
        init_security_dir(d, ["planner"])
    d.chmod(0o755)
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    for pid in range(os.getpid() - 2, os.getpid() + 3):  # the old temporary name was .<name>.<pid>.tmp
        (d / f".planner.crt.{pid}.tmp").symlink_to(victim)
    init_security_dir(d, ["planner"])
    assert victim.read_text() == "mine" and verify_role(d, "planner")


def test_a_private_key_others_may_read_is_refused_naming_the_fix(tmp_path: Path) -> None:
    init_security_dir(tmp_path, ["planner"])
    (tmp_path / "planner.key").chmod(0o644)
    with pytest.raises(CertificateError, match=r"planner\.key: others than its owner may read it \(mode 644\): "
                                               r"chmod 600"):
        verify_role(tmp_path, "planner")



def test_an_authority_key_others_may_read_is_refused_and_check_says_so(tmp_path: Path, capsys) -> None:
    """A world-readable ca.key signed new certificates and `check` printed ok (a security review): whoever read it can
    issue any role."""
    assert main(["init", str(tmp_path)]) == 0
    capsys.readouterr()
    (tmp_path / "ca.key").chmod(0o644)
    with pytest.raises(CertificateError, match=r"ca\.key: others than its owner may read it \(mode 644\).*--new-ca"):
        init_security_dir(tmp_path, ["planner"])
    assert main(["check", str(tmp_path)]) == 1
    assert "ca.key: " in capsys.readouterr().out
    (tmp_path / "ca.key").chmod(0o600)
    assert main(["check", str(tmp_path)]) == 0
    assert "keep it only on the machine that issues them" in capsys.readouterr().out


def test_a_rotation_says_it_locks_no_old_certificate_out(tmp_path: Path, capsys) -> None:
    """There is no revocation: a rotation keeps the authority, and a leaked certificate stays valid with it."""
    assert main(["init", str(tmp_path)]) == 0
    assert "--new-ca" not in capsys.readouterr().out
    assert main(["init", str(tmp_path)]) == 0
    assert "locked out only by --new-ca" in capsys.readouterr().out

def test_a_file_that_is_not_pem_is_named(tmp_path: Path) -> None:
    init_security_dir(tmp_path, ["planner"])
    (tmp_path / "planner.crt").write_text("not a certificate")
    with pytest.raises(CertificateError, match=r"planner\.crt: not a PEM certificate"):
        verify_role(tmp_path, "planner")
    (tmp_path / "ca.key").write_text("garbage")
    with pytest.raises(CertificateError, match=r"ca\.key: not a PEM key"):
        init_security_dir(tmp_path, ["planner"])
    with pytest.raises(FileNotFoundError, match="does not exist"):
        verify_role(tmp_path / "typo", "planner")


def test_days_past_the_authority_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    with pytest.raises(CertificateError, match="at most 3650"):
        init_security_dir(tmp_path / "new", ["planner"], days=10**6)
    assert not any((tmp_path / "new").iterdir())
    init_security_dir(tmp_path / "old", ["planner"])
    with pytest.raises(CertificateError, match="cannot outlive it"):
        init_security_dir(tmp_path / "old", ["planner"], days=4000)


def test_no_role_certificate_outlives_its_authority(tmp_path: Path) -> None:
    authority = make_authority(days=1)
    end = authority.certificate.not_valid_after_utc
    assert issue(authority, "planner", days=365).certificate.not_valid_after_utc == end  # it ran a year past it
    init_security_dir(tmp_path, ["planner"], days=3650)  # the authority's validity: both end together, not ms apart
    ca = x509.load_pem_x509_certificate((tmp_path / "ca.crt").read_bytes())
    assert verify_role(tmp_path, "planner").not_valid_after_utc <= ca.not_valid_after_utc


def test_check_on_a_cell_machine_checks_the_roles_it_holds_and_names_their_hosts(tmp_path: Path, capsys) -> None:
    """docs/security.md copies a machine's own roles only: check failed on every role the machine lacks."""
    full, robot = tmp_path / "full", tmp_path / "robot"
    assert main(["init", str(full), "--hosts", "robot.local"]) == 0
    robot.mkdir(mode=0o755)
    for name in ("ca.crt", "router.crt", "router.key", "executor.crt", "executor.key"):
        (robot / name).write_bytes((full / name).read_bytes())
        (robot / name).chmod((full / name).stat().st_mode)
    capsys.readouterr()
    assert main(["check", str(robot)]) == 0
    out = capsys.readouterr().out
    assert "router: ok, valid until" in out and "hosts robot.local, localhost, 127.0.0.1" in out
    assert "executor: ok" in out and "planner" not in out.split("not on this machine:")[0]
    assert main(["check", str(robot), "--role", "planner"]) == 1  # asked for: missing is an error
    assert "planner.crt is missing" in capsys.readouterr().out


def test_a_ca_file_others_may_write_or_holding_a_second_authority_is_refused(tmp_path: Path) -> None:
    """A 0666 ca.crt in a 0700 directory passed, and so did a ca.crt with another CA appended: Zenoh trusts every
    certificate in it, and that CA's 'planner' was let in."""
    d = tmp_path / "cell"
    init_security_dir(d, ["planner"])
    verify_role(d, "planner")
    (d / "ca.crt").chmod(0o666)
    with pytest.raises(ValueError, match=r"security file .*ca.crt: writable by others \(mode 666\)"):
        verify_role(d, "planner")
    (d / "ca.crt").chmod(0o644)
    (d / "planner.crt").chmod(0o664)
    with pytest.raises(ValueError, match=r"planner.crt: writable by its group"):
        verify_role(d, "planner")
    (d / "planner.crt").chmod(0o644)
    (d / "ca.crt").write_bytes((d / "ca.crt").read_bytes() + make_authority().cert_pem)
    with pytest.raises(ValueError, match="ca.crt: holds 2 certificates"):
        verify_role(d, "planner")
    (d / "ca.crt").write_bytes((d / "planner.crt").read_bytes())  # a role's certificate copied over it
    with pytest.raises(ValueError, match="ca.crt: not a certificate authority"):
        verify_role(d, "planner")


def test_an_expired_authority_is_named_by_check_and_by_a_rotation(tmp_path: Path) -> None:
    """An authority expired 9 days ago, its role certificates valid: `check` said ok, the handshake check blamed the
    router's certificate, and `init` rotated under it ("ends on ..., in -9 days")."""
    now = dt.datetime.now(dt.UTC)
    authority = make_authority(days=10, now=now - dt.timedelta(days=19))
    role = issue(authority, "planner", now=now, not_after=now + dt.timedelta(days=30))
    d = tmp_path / "cell"
    d.mkdir(mode=0o700)
    for name, data in (("ca.crt", authority.cert_pem), ("ca.key", authority.key_pem), ("planner.crt", role.cert_pem),
                       ("planner.key", role.key_pem)):
        (d / name).write_bytes(data)
        (d / name).chmod(0o600 if name.endswith(".key") else 0o644)
    with pytest.raises(CertificateError, match=r"^ca.crt \(the authority\): expired at "):
        verify_role(d, "planner")
    with pytest.raises(CertificateError, match=r"^ca.crt \(the authority\): expired at .* issue new certificates"):
        init_security_dir(d, ["planner"])
    assert (d / "planner.crt").read_bytes() == role.cert_pem  # nothing rotated under it


def test_a_second_authority_in_ca_crt_stops_a_rotation(tmp_path: Path) -> None:
    """`init` reused a ca.crt with another CA appended (rc 0), and handed the tampered file out with the new ones."""
    d = tmp_path / "cell"
    init_security_dir(d, ["planner"])
    (d / "ca.crt").write_bytes((d / "ca.crt").read_bytes() + make_authority().cert_pem)
    before = (d / "planner.crt").read_bytes()
    with pytest.raises(CertificateError, match="ca.crt: holds 2 certificates"):
        init_security_dir(d, ["planner"])
    assert (d / "planner.crt").read_bytes() == before


def test_init_puts_its_files_on_disk(tmp_path: Path, monkeypatch) -> None:
    """No file was flushed (18 files, 0 fsync calls): a crash soon after a first init could leave an empty ca.key."""
    synced: list[int] = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(fd), real(fd))[1])
    written = init_security_dir(tmp_path / "cell", ["planner", "executor"])
    assert len(synced) == len(written) + 1  # each file, then the directory (the renames)


def test_init_makes_its_directory_0700_whatever_the_umask(tmp_path: Path) -> None:
    """Under umask 002 (Ubuntu's for users with their own group) init refused the directory it had just made."""
    import os

    old = os.umask(0o002)
    try:
        init_security_dir(tmp_path / "cell", ["planner"])
    finally:
        os.umask(old)
    assert (tmp_path / "cell").stat().st_mode & 0o777 == 0o700


def test_a_key_this_user_cannot_read_names_its_owner_and_this_user(tmp_path: Path, monkeypatch) -> None:
    """A container run as another user than the one who made the keys read only '...router.key: Permission
    denied' (a review of docker compose with compose.secure.yaml)."""
    import shared.security.certificates as certificates

    init_security_dir(tmp_path, ["router"], hosts=["router"])
    key = tmp_path / "router.key"
    if os.getuid() == 0:  # root reads every file: the check is made to see what another user would
        monkeypatch.setattr(certificates.os, "access", lambda path, mode: Path(path) != key)
    else:
        key.chmod(0)
    with pytest.raises(CertificateError, match=r"router\.key: this process \(uid \d+\) cannot read it \(owner uid "
                                               r"\d+, mode (600|0)\).*containers run as the owner of runs/"):
        verify_role(tmp_path, "router")


def test_a_directory_this_user_cannot_write_is_named_before_any_file(tmp_path: Path, monkeypatch) -> None:
    """A `security/` directory Docker had made, root's: `security init` failed naming a temporary file of its own
    ('.ca.crt.XXXX.tmp: Permission denied'), not the directory (a review)."""
    import shared.security.certificates as certificates

    d = tmp_path / "security"
    d.mkdir(mode=0o700)
    if os.getuid() == 0:  # root writes everywhere: the check is made to see what another user would
        monkeypatch.setattr(certificates.os, "access", lambda path, mode: Path(path) != d)
    else:
        d.chmod(0o500)
    with pytest.raises(PermissionError, match=r"cannot write into it \(owned by uid \d+; chown it or remove it\)") as e:
        init_security_dir(d, ["router"])
    assert e.value.filename == str(d) and not list(d.iterdir())
