"""Files written whole: a temporary file beside the target, renamed onto it when complete.

A reader (or a crash, a full disk, Ctrl-C) never sees half a file: the target is either the old file
or the new one. Used for every output a later run reads back (libraries, certificates, compressed
logs, cached fits). Beside it, the checks made before the work: a path that can be written
(:func:`ready_to_write`), a file that cannot be read (:func:`unreadable`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = ["atomic_write", "make_parent", "ready_to_write", "unreadable"]


def make_parent(path: str | os.PathLike[str]) -> Path:
    """Create ``path``'s parent directories; returns ``path`` as a :class:`Path`.

    Raises:
        NotADirectoryError: A part of the parent path is a file (mkdir's own error says "File exists").
    """
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):  # mkdir says "File exists" or "Not a directory", naming no culprit
        blocker = next((a for a in reversed(p.parents) if a.exists() and not a.is_dir()), p.parent)
        raise NotADirectoryError(errno.ENOTDIR, "a file is in the way (a directory is needed there)",
                                 str(blocker)) from None
    return p


def ready_to_write(path: str | os.PathLike[str], directory: bool = False) -> Path:
    """Check, before the work that makes it, that ``path`` can be written: its parents made, nothing in the way.

    Args:
        path: A file to write (or, with ``directory``, a directory to write into).
        directory: ``path`` is a directory (created).

    Raises:
        NotADirectoryError: A file is where a directory is needed (named).
        IsADirectoryError: ``path`` is a directory where a file is to be written.
        PermissionError: The directory it goes in is not writable.
    """
    p = Path(path)
    target = make_parent(p / "x").parent if directory else make_parent(p).parent  # directory: p itself is made
    if not directory and p.is_dir():
        raise IsADirectoryError(errno.EISDIR, "a directory is in the way (a file is to be written there)", str(p))
    if not os.access(target, os.W_OK | os.X_OK):
        raise PermissionError(errno.EACCES, "not writable by this user", str(target))
    return p


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: int = 0o644, fsync: bool = False) -> Iterator[BinaryIO]:
    """Yield a binary file that takes ``path``'s name only when the ``with`` block ends without an error.

    Args:
        path: The target (its parent directories are created); an existing file is replaced, never written
            into, whatever its permissions.
        mode: Permissions of the new file, set before a byte is written (0o600 for a private key).
        fsync: Flush the file to disk before the rename (a crash then leaves the old file or the whole new one).

    On an error (or Ctrl-C) in the block the temporary file is removed and ``path`` is left as it was.
    """
    p = make_parent(path)
    fd, name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)  # a new file: never one planted
    tmp = Path(name)
    try:
        os.fchmod(fd, mode)  # whatever the umask gave
        with os.fdopen(fd, "wb") as f:
            yield f
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def unreadable(path: str | os.PathLike[str]) -> str:
    """Why this process cannot read the file at ``path``, in words naming its owner and mode; ``""`` if it can.

    The counterpart of :func:`ready_to_write`'s check, for a file written by another user (a container's, a key
    kept private to its owner): "Permission denied" alone named neither.
    """
    if os.access(path, os.R_OK):
        return ""
    st = Path(path).stat()
    return f"this process (uid {os.getuid()}) cannot read it (owner uid {st.st_uid}, mode {st.st_mode & 0o777:o})"
