"""A binary file whose writes go straight to the OS: what the MCAP writer writes is on disk at once.

The ``mcap`` writer buffers a whole chunk itself; a second buffer in between would hold back the end
of a log from a reader, and from a crash.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["DirectFile"]


class DirectFile:
    """A binary file whose writes go straight to the OS (the mcap writer buffers a chunk itself)."""

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pos = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Write all of ``data``; returns its length."""
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
            self._pos += n
        return len(data)

    def tell(self) -> int:
        """Bytes written so far."""
        return self._pos

    def flush(self) -> None:
        """Nothing is buffered here."""

    def fsync(self) -> None:
        """Ask the OS to put what was written on the disk."""
        os.fsync(self._fd)

    def close(self) -> None:
        """Close the file (once)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
