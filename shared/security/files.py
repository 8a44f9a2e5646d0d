"""A security directory's files: present, readable by this process, private, and writable by nobody else.

What :func:`shared.security.certificates.verify_role` checks before it reads a certificate or a key, and what
``foresight security check`` names when one fails: every error names the file, what is wrong and the fix.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from shared.atomic_file import unreadable

__all__ = ["CertificateError", "read_role", "check_directory", "check_readable", "check_private"]


class CertificateError(ValueError):
    """A role's certificate or key that cannot be used; the message names the file and what is wrong."""


def read_role(directory: str | os.PathLike[str], role: str) -> tuple[Path, Path, Path]:
    """``(ca.crt, <role>.crt, <role>.key)`` of a security directory.

    Raises:
        FileNotFoundError: Naming the missing file and how to make it.
    """
    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"security directory {d} does not exist (make one with `foresight security init DIR`)")
    files = (d / "ca.crt", d / f"{role}.crt", d / f"{role}.key")
    for f in files:
        if not f.is_file():
            raise FileNotFoundError(f"security directory {d}: {f.name} is missing (make the certificates with "
                                    f"`foresight security init DIR` where the cell's ca.key is, and copy ca.crt "
                                    f"and this role's files here)")
    return files


def check_readable(path: Path) -> None:
    """Refuse a file this process cannot read, naming its owner and this process's user.

    A key is written readable by its owner only: a service run as another user (a container, whose user is the
    owner of the mounted runs/ directory: docs/docker.md) read only "Permission denied".

    Raises:
        CertificateError: Naming the file, its owner and mode, and this process's user.
    """
    if why := unreadable(path):
        raise CertificateError(f"{path}: {why}: run the service as its owner, or give the security directory to this "
                               f"user (chown -R {os.getuid()} DIR); under Docker the containers run as the owner of "
                               "runs/ (docs/docker.md)")


def check_private(key_path: Path, then: str = "") -> None:
    """Refuse a key that others than its owner may read (``then``: what to do besides ``chmod 600``).

    Raises:
        CertificateError: Naming the key and its mode.
    """
    if (mode := key_path.stat().st_mode & 0o777) & 0o077:
        raise CertificateError(f"{key_path}: others than its owner may read it (mode {mode:o}): chmod 600 {key_path}"
                               + (f"; {then}" if then else ""))


def check_directory(directory: str | os.PathLike[str], files: Sequence[str] = ("ca.crt",)) -> None:
    """Refuse a security directory, or a file of it, that someone else may write.

    Whoever may write them could put an authority of their own in ca.crt (Zenoh trusts every certificate that file
    holds), or replace a role's certificate and key.

    Args:
        directory: The security directory.
        files: Its files to check as well, where they exist (followed where they are links: what is read counts).

    Raises:
        CertificateError: The directory or one of ``files`` is writable by its group or others, or belongs to
            another user (root excepted).
    """
    d = Path(directory)
    for path, what in ((d, "security directory"), *((d / f, "security file") for f in files if (d / f).exists())):
        st = path.stat()
        if st.st_mode & 0o022:
            raise CertificateError(f"{what} {path}: writable by {'others' if st.st_mode & 0o002 else 'its group'} "
                                   f"(mode {st.st_mode & 0o777:o}); whoever can write it can put an authority of "
                                   f"their own in ca.crt: chmod go-w {path}")
        if st.st_uid not in (os.getuid(), 0):
            raise CertificateError(f"{what} {path}: belongs to user id {st.st_uid}, not to this user "
                                   f"({os.getuid()}) or root; its owner could put an authority of their own in ca.crt")
