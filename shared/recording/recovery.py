"""A log's records read past its damage: a damaged chunk skipped, a damaged attachment left out, each counted.

:class:`Records` breaks each chunk up itself (the stream reader emits them whole), so that one chunk failing its CRC
does not end the reading: in a finished log whose summary is intact, the chunk is skipped and the others are read (its
messages counted from the message indexes after it); one flipped byte lost every chunk after it, and the tools called
the log TRUNCATED (a review). Elsewhere (a log without its footer: killed, or still being written) reading stops at the
damaged chunk, as at a cut, and the damage is still named. Attachments are checked against their own CRC, which the
mcap library skips, and a data section that fails its CRC (a metadata record changed) is named as such.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile, McapError
from mcap.records import Attachment, Chunk, DataEnd, Footer, Header, McapRecord, MessageIndex
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

from shared.runtime import UserError

__all__ = ["Bounded", "Records", "DAMAGED", "describe"]

DAMAGED = (McapError, struct.error, ValueError, EOFError, zstandard.ZstdError, RuntimeError, MemoryError,
           OverflowError)
"""What reading a damaged MCAP raises: the mcap library's errors, a record cut short (``struct.error``,
``EOFError``), a chunk whose CRC does not match (``CRCValidationError``, a ``ValueError``), and a compressed chunk
that does not decompress (zstandard's ``ZstdError``; lz4 raises ``RuntimeError``), and, as a backstop, a damaged
length that asks for more memory than there is."""

_CUT = (EndOfFile, struct.error, EOFError)
"""What a record cut short by the file's end raises."""


def describe(exc: BaseException) -> str:
    """An exception in the readers' words: its type, and its message where it has one."""
    name = "struct.error" if isinstance(exc, struct.error) else type(exc).__name__  # not a bare "error"
    return f"{name}: {exc}" if str(exc) else name


class Bounded:
    """A file whose reads never ask for more than the bytes it has left, and that keeps its last read.

    A damaged length inside a record (an attachment's, say) then reads to the end of the file and fails there,
    instead of allocating exabytes. ``last`` is what the last read returned: after an attachment, its CRC.
    """

    def __init__(self, f: io.BufferedReader, size: int) -> None:
        self._f, self._left, self.last = f, size, b""

    def read(self, n: int = -1) -> bytes:
        """At most ``n`` bytes (all that are left when ``n`` is negative), kept as ``last``."""
        data = self._f.read(self._left if n is None or n < 0 else min(n, self._left))
        self._left -= len(data)
        self.last = data
        return data


def _attachment_crc(rec: Attachment) -> int:
    """The CRC an attachment's fields give (the writer's: over the record less its opcode, length and CRC)."""
    builder = RecordBuilder()
    rec.write(builder)
    return int.from_bytes(bytes(builder.end())[-4:], "little")


class Records:
    """The records of a log opened with ``emit_chunks``, in file order, each chunk's records in its place.

    Attributes:
        skipped: Chunks that failed their CRC (or to decompress) and were skipped.
        lost: Messages in the skipped chunks, from their message indexes; None where a skipped chunk had none.
        damage: What was found damaged, in words ("" when nothing was): the chunks skipped, the chunk reading stopped
            at, an attachment or the data section failing its CRC.
        ended: The footer and the closing magic were read, or (a finished log) the data section's CRC failed where
            the footer follows.
        started: The header was read.
    """

    def __init__(self, reader: StreamReader, source: Bounded, skip: bool,
                 known: list[McapRecord] | None = None) -> None:
        """Read ``reader``'s records.

        Args:
            reader: The log's records, chunks emitted whole.
            source: What ``reader`` reads from.
            skip: The log ends as a finished one and its summary is intact: a damaged chunk is skipped.
            known: The summary's schemas and channels, given after the header: a skipped chunk may have held the
                first record of a channel whose messages follow in other chunks.
        """
        self._reader, self._source, self._skip, self._known = reader, source, skip, known or []
        self.skipped, self.damage = 0, ""
        self.lost: int | None = 0
        self._first = ""
        self.ended = self.started = False

    def _note_skipped(self) -> None:
        lost = "" if self.lost is None else f": {self.lost} message{'s' * (self.lost != 1)} lost"
        n = self.skipped
        their = "their" if n > 1 else "its"
        self.damage = f"{n} chunk{'s' * (n != 1)} failing {their} CRC skipped{lost} ({self._first})"

    def __iter__(self) -> Iterator[McapRecord]:
        """The records; a cut or damage that ends the reading is raised (one of :data:`DAMAGED`).

        Raises:
            UserError: The file ends, or is damaged, before its header ends: there is nothing to read.
        """
        it = iter(self._reader.records)
        counting = indexed = footer = False  # the message indexes after a skipped chunk: its messages
        while True:
            try:
                rec = next(it)
            except StopIteration:  # after the footer, the closing magic: a copy cut within it is not finished
                self.ended = footer
                return
            except CRCValidationError as exc:
                if not isinstance(exc.record, DataEnd):
                    raise
                if not self.skipped:  # a skipped chunk fails the data section's CRC too: already said
                    self.damage = self.damage or ("metadata/attachments: the data section fails its CRC (a record "
                                                  f"outside the chunks is damaged; {describe(exc)})")
                self.ended = self._skip  # the footer and summary after it are whole
                return
            except DAMAGED as exc:
                if self.started:  # a finished log's records are all there: what stops them is damage, not a cut
                    self.damage = self.damage or (f"{describe(exc)}: read up to it" if self._skip else "")
                    raise
                why = "truncated before its header ends" if isinstance(exc, _CUT) else "its header is damaged"
                raise UserError(f"not an MCAP file: {why} ({describe(exc)})") from None
            if isinstance(rec, Header):
                self.started = True
                yield rec
                yield from self._known
                continue
            if not self.started:
                raise UserError(f"not an MCAP file: its first record is no header ({type(rec).__name__})")
            if isinstance(rec, Chunk):
                try:
                    inner = breakup_chunk(rec, validate_crc=True)
                except DAMAGED as exc:
                    self._first = self._first or describe(exc)
                    if not self._skip:
                        self.damage = f"a chunk failing its CRC ({describe(exc)}): read up to it"
                        raise
                    self.skipped += 1
                    counting, indexed = True, False
                    self._note_skipped()
                    continue
                counting = False
                yield from inner
                continue
            if isinstance(rec, MessageIndex):
                if counting and self.lost is not None:
                    self.lost += len(rec.records)
                    indexed = True
                    self._note_skipped()
                continue
            if counting and not indexed:  # a skipped chunk without message indexes: its messages are not known
                self.lost = None
                self._note_skipped()
            counting = False
            if isinstance(rec, Attachment):
                stored = int.from_bytes(self._source.last, "little") if len(self._source.last) == 4 else 0
                if stored and stored != _attachment_crc(rec):
                    self.damage = self.damage or (f"metadata/attachments: the attachment {rec.name!r} fails its CRC "
                                                  f"({stored:#010x} stored, {_attachment_crc(rec):#010x} read)")
                    continue  # left out: a damaged scene.toml would be drawn as the run's scene
            footer = footer or isinstance(rec, Footer)
            yield rec
