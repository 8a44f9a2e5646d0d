"""Files written whole: a temporary file beside the target, renamed onto it when complete.

A reader (or a crash, a full disk, Ctrl-C) never sees half a file: the target is either the old file
or the new one. Used for every output a later run reads back (libraries, certificates, compressed
logs, cached fits). Beside it, the checks made before the work: a path that can be written
(:func:`ready_to_write`), one that may be replaced (:func:`replaceable`: a regular file or a link, never a device
or a pipe), a file that cannot be read (:func:`unreadable`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = ["atomic_write", "make_parent", "not_a_file", "ready_to_write", "replaceable", "unreadable"]

_KINDS = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device", stat.S_IFIFO: "a named pipe (FIFO)",
          stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a directory"}


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


def not_a_file(path: str | os.PathLike[str], follow: bool = False) -> str:
    """What is at ``path``, in words, when it is no regular file (``"a named pipe (FIFO)"``); else ``""``.

    Args:
        path: The path.
        follow: Look at a symbolic link's target (a file opened through the link); else a link counts as a file
            (it is replaced itself, see :func:`replaceable`).
    """
    try:
        mode = os.stat(path).st_mode if follow else os.lstat(path).st_mode
    except FileNotFoundError:
        return ""
    if stat.S_ISREG(mode) or (not follow and stat.S_ISLNK(mode)):
        return ""
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")


def replaceable(path: str | os.PathLike[str]) -> None:
    """Refuse to replace ``path`` when something other than a regular file or a symbolic link is there.

    A rename onto a device or a pipe replaced it with a regular file: ``foresight log compress X /dev/null`` run as
    root left the machine without its ``/dev/null`` (a review). A symbolic link is replaced itself, whatever it points
    to (its target, a file or a device, is left alone): the new file never lands outside the directory named.

    Raises:
        IsADirectoryError: A directory is there (named).
        FileExistsError: A device, a named pipe or a socket is there (named, with its kind).
    """
    kind = not_a_file(path)
    if kind == _KINDS[stat.S_IFDIR]:
        raise IsADirectoryError(errno.EISDIR, "a directory is in the way (a file is to be written there)", str(path))
    if kind:
        raise FileExistsError(errno.EEXIST, f"{kind} is there, not a regular file: left alone; give a file's path",
                              str(path))


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: int = 0o644, fsync: bool = False) -> Iterator[BinaryIO]:
    """Yield a binary file that takes ``path``'s name only when the ``with`` block ends without an error.

    Args:
        path: The target (its parent directories are created); an existing file is replaced, never written
            into, whatever its permissions; a symbolic link is replaced itself (its target left alone); a device,
            a pipe, a socket or a directory there is refused (:func:`replaceable`), before the block runs.
        mode: Permissions of the new file, set before a byte is written (0o600 for a private key).
        fsync: Flush the file to disk before the rename (a crash then leaves the old file or the whole new one).

    On an error (or Ctrl-C) in the block the temporary file is removed and ``path`` is left as it was.
    """
    p = make_parent(path)
    replaceable(p)
    fd, name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)  # a new file: never one planted
    tmp = Path(name)
    try:
        os.fchmod(fd, mode)  # whatever the umask gave
        with os.fdopen(fd, "wb") as f:
            yield f
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        replaceable(p)  # again: one made while the block ran (a pipe, a device node) is not replaced either
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
