"""A binary file whose writes go straight to the OS: what the MCAP writer writes is on disk at once.

The ``mcap`` writer buffers a whole chunk itself; a second buffer in between would hold back the end
of a log from a reader, and from a crash.

A write the OS refuses (a full disk) is not half-done: the bytes it did not take are held, in order, and
written before anything else once it takes them again, so a log whose disk was full for a while is whole
once space returns. Only past :data:`MAX_HELD_BYTES` held does a write fail, and every later one: the
file then ends where the disk stopped taking bytes, which readers treat like the end of a killed run.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import time
from pathlib import Path

from shared.atomic_file import not_a_file

__all__ = ["DirectFile", "MAX_HELD_BYTES"]

log = logging.getLogger("foresight.recording")

NO_LOCKS = (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL)
"""What ``flock`` answers on a file system that takes no lock (NFS without its lock daemon, some FUSE mounts): the
log is written without one, as before the lock was taken."""

MAX_HELD_BYTES = 64 * 2 ** 20
"""Most bytes held in memory while the OS refuses them (about a minute of a real-time run's log)."""


class DirectFile:
    """A binary file whose writes go straight to the OS (the mcap writer buffers a chunk itself).

    Attributes:
        refusals: Writes the OS refused (their bytes held, then written once it took them again).
    """

    def __init__(self, path: Path) -> None:
        """Create or empty ``path`` for writing, holding an exclusive lock on it while open.

        Raises:
            OSError: The OS refuses the path, it is no regular file (a device, a pipe: named, left alone), or
                another process is writing the file (its lock): that log is left alone (before, the second writer
                emptied it and the first one's messages were lost without a word).
        """
        self._path = path
        if kind := not_a_file(path, follow=True):  # a pipe would block the open; a device fails in ftruncate
            raise OSError(errno.EINVAL, f"{kind} is there, not a regular file: give a file's path for the log",
                          str(path))
        # non-blocking: a pipe made since the check fails here instead of waiting for a reader
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK, 0o644)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, fcntl.fcntl(self._fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._fd)
            raise OSError(errno.EBUSY, f"{path}: another run is writing this log (its lock); give another "
                          "path") from None
        except OSError as exc:
            if exc.errno not in NO_LOCKS:
                os.close(self._fd)
                raise OSError(exc.errno, f"cannot lock the log ({exc.strerror})", str(path)) from None
            log.warning("mcap log %s: this file system takes no lock (%s): written without one", path, exc.strerror)
        try:
            os.ftruncate(self._fd, 0)
        except OSError as exc:  # its errno alone ("Invalid argument") named neither the file nor the step
            os.close(self._fd)
            raise OSError(exc.errno, f"cannot empty the file for the log ({exc.strerror})", str(path)) from None
        self._pos = 0
        self._held = bytearray()
        self._failed: OSError | None = None
        self.refusals = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Take all of ``data``; returns its length.

        Raises:
            OSError: The OS refused bytes and :data:`MAX_HELD_BYTES` are held, or it did before (the file
                ends where it stopped taking them).
        """
        if self._failed is not None:
            raise OSError(self._failed.errno, f"{self._path}: the log ended at {self._pos - len(self._held)} bytes "
                          f"({self._failed.strerror})")
        if self._held:
            self._held += data
        else:
            self._write_through(memoryview(data).cast("B"))
        self._pos += len(data)
        self._drain()
        return len(data)

    def _write_through(self, view: memoryview) -> None:
        while view:
            try:
                n = os.write(self._fd, view)
            except OSError:
                self._held += view  # the rest, in order: written first once the OS takes bytes again
                return
            view = view[n:]

    def _drain(self) -> None:
        while self._held:
            try:
                n = os.write(self._fd, self._held)
            except OSError as exc:
                self.refusals += 1
                ending = len(self._held) > MAX_HELD_BYTES and self._failed is None  # said once: a close retries
                if self.refusals == 1 or ending:
                    log.warning("mcap log %s: the OS refused a write (%s); %d bytes held until it takes them",
                                self._path, exc.strerror, len(self._held))
                if ending:
                    self._failed = exc
                    raise OSError(exc.errno, f"{self._path}: {len(self._held)} bytes refused by the OS "
                                  f"({exc.strerror}); the log ends at {self._pos - len(self._held)} bytes") from None
                return
            del self._held[:n]
            if not self._held and self.refusals:
                log.warning("mcap log %s: the OS takes writes again; nothing held is lost%s", self._path,
                            " (the log still ends there)" * (self._failed is not None))

    @property
    def failed(self) -> OSError | None:
        """The OS's refusal that ended the file (None while it takes bytes): every later write fails."""
        return self._failed

    @property
    def held(self) -> int:
        """Bytes taken but not yet written (the OS refused them)."""
        return len(self._held)

    @property
    def removed(self) -> bool:
        """Whether the file has no name left on the disk (it, or its directory, was deleted while open)."""
        return self._fd >= 0 and os.fstat(self._fd).st_nlink == 0

    def tell(self) -> int:
        """Bytes taken so far (written or held)."""
        return self._pos

    def flush(self) -> None:
        """Try to write what is held; nothing else is buffered here."""
        if self._held and self._failed is None:
            self._drain()

    def drain(self, timeout_s: float, poll_s: float = 0.05) -> int:
        """Retry writing what is held for at most ``timeout_s`` (a close: space may come back); returns bytes held.

        Also after the file ended (:attr:`failed`): what is held is a whole prefix of the records it was given, and
        every byte of it written makes more of the log readable.
        """
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            if self._held:
                try:
                    self._drain()
                except OSError:  # past MAX_HELD_BYTES: still held, tried again until the deadline
                    pass
            if not self._held or time.monotonic() >= deadline:
                return len(self._held)
            time.sleep(min(poll_s, max(0.0, deadline - time.monotonic())))

    def fsync(self) -> None:
        """Write what is held and ask the OS to put the file on the disk.

        Raises:
            OSError: Bytes are still held (the OS refuses them): the file ends before them.
        """
        self.flush()
        if self._held:
            raise OSError(28, f"{self._path}: {len(self._held)} bytes could not be written; the log ends at "
                          f"{self._pos - len(self._held)} bytes")
        os.fsync(self._fd)

    def close(self) -> None:
        """Close the file (once); what is still held is lost (:meth:`drain` and :meth:`fsync` first)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
