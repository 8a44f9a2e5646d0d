"""Which of a log's messages are on the disk: what a close says when a full disk cost some (:class:`Ledger`).

The writer notes where each chunk ends in the file (every message before it is in it); the file
(:class:`~shared.recording.direct_file.DirectFile`) says how many of its bytes the OS took. A chunk counts once
the OS took all of its bytes (a reader recovers a chunk whole or not at all).
"""

from __future__ import annotations

import errno
import os
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .direct_file import DirectFile

__all__ = ["Ledger"]


class Ledger:
    """Counts of a log's messages: taken by the writer, refused at once, on the disk.

    Attributes:
        total: Messages the writer took.
        refused: Messages refused at once (the file had ended: past what it holds).
        lost: Of ``total + refused``, those not on the disk when the log was closed (set by :meth:`closed`).
    """

    def __init__(self, file: DirectFile, writer: Any = None) -> None:
        self._file = file
        self._writer = writer  # an mcap Writer: where its last chunk ends (its message indexes are not needed)
        self._marks: deque[tuple[int, int]] = deque()  # (file offset after a chunk, messages up to its end)
        self._on_disk = 0
        self.total = 0
        self.refused = 0
        self.lost = 0

    def mark(self, since: int = 0) -> None:
        """Every message so far is in the file's bytes up to here (call it right after a chunk written from ``since``).

        Up to the end of that chunk where the writer says (``mcap``'s chunk index): a reader recovers it whole without
        the message indexes after it; otherwise up to here (a chunk whose bytes ended the file, or another writer).
        """
        if not self._marks or self._marks[-1][1] != self.total:
            end = self._file.tell()
            chunks = getattr(self._writer, "_Writer__chunk_indices", None)
            if chunks and since <= chunks[-1].chunk_start_offset < end:
                end = chunks[-1].chunk_start_offset + chunks[-1].chunk_length
            self._marks.append((end, self.total))
            self._settle()

    @contextmanager
    def writing(self) -> Iterator[None]:
        """Around a writer call: a chunk it wrote holds every message so far.

        Even a chunk whose bytes ended the file (past what it holds): they are held all the same, retried at the close.
        """
        offset = self._file.tell()
        try:
            yield
        finally:
            if self._file.tell() != offset:
                self.mark(offset)

    @property
    def written(self) -> int:
        """Messages on the disk: those of the chunks whose bytes the OS has all taken."""
        return self._settle()

    def _settle(self) -> int:
        """Drop the marks of chunks now on the disk (one a flush: a day's run kept 86 000); the messages on it."""
        done = self._file.tell() - self._file.held
        while self._marks and self._marks[0][0] <= done:
            self._on_disk = self._marks.popleft()[1]
        return self._on_disk

    def closed(self, path: Path, removed: bool, error: OSError | None) -> OSError | None:
        """Set :attr:`lost` at the close; the one-line error to raise when the log is not complete (None: it is).

        Args:
            path: The log.
            removed: Its file was deleted while written (every message is lost).
            error: Why the close could not finish it (a full disk), or None.
        """
        total = self.total + self.refused
        self.lost = total if removed else total - self.written
        if not (removed or self.lost or error is not None):
            return None
        if removed:
            why = f"the file was deleted while it was written (or its directory): its {total} messages are lost"
            code = errno.ENOENT
        else:
            code = error.errno if error is not None and error.errno else errno.EIO
            why = f"{os.strerror(code)}: {error.strerror or error}" if error is not None else "not finished"
        return OSError(code, f"{path}: INCOMPLETE: {total - self.lost} of {total} messages written ({why})")
