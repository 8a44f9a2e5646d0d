"""The MCAP reader: a run's log read record by record, tolerating a truncated end.

:func:`read_log` goes through the file with mcap's stream reader, so it needs no summary section:
a file whose writer was killed is read up to its last complete chunk (``LogFile.complete`` is then
False and ``LogFile.error`` says why reading stopped). The records it understands are the ones
:mod:`shared.recording.writer` writes: header, schemas, channels, messages, attachments, metadata.
"""

from __future__ import annotations

import fcntl
import io
import os
import struct
import typing
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import zstandard
from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from shared.runtime import UserError

__all__ = ["LogChannel", "LogMessage", "LogFile", "read_log", "iter_messages", "open_records", "log_path", "DAMAGED",
           "MAGIC", "summary_damage", "being_written", "ends_finished", "SOURCE_METADATA", "STILL_WRITTEN"]

SOURCE_METADATA = "foresight.compress"
"""Metadata record of a copy made from a truncated or damaged log (``foresight log compress``): ``source``,
``source_complete`` = "false" and ``source_error`` (``foresight log info`` shows it: the copy is whole, what it was
copied from was not)."""

STILL_WRITTEN = "still being written when copied: up to its last whole chunk then"
"""``source_error`` of a copy of a log a run was still writing."""

MAGIC = b"\x89MCAP0\r\n"
"""The first (and last) eight bytes of an MCAP file."""

DAMAGED = (McapError, struct.error, ValueError, EOFError, zstandard.ZstdError, RuntimeError, MemoryError,
           OverflowError)
"""What reading a damaged MCAP raises: the mcap library's errors, a record cut short (``struct.error``,
``EOFError``), a chunk whose CRC does not match (``CRCValidationError``, a ``ValueError``), and a compressed chunk
that does not decompress (zstandard's ``ZstdError``; lz4 raises ``RuntimeError``), and, as a backstop, a damaged
length that asks for more memory than there is. Every reader of the logs reads through :func:`open_records`
(``validate_crcs=True``, no read past the file's end) and stops at the first of these: what came before stands."""


_FOOTER = struct.Struct("<BQQQI")
"""The footer record: opcode 0x02, its length (20), summary start, summary offset start, summary CRC."""


def summary_damage(path: str | Path) -> str:
    """Why a finished log's summary section (its index) cannot be trusted; "" when it can or there is none.

    The footer holds the CRC of the summary, which the readers did not check: with one bit of a chunk index flipped,
    ``foresight log info`` said "complete" and ``foresight log snapshot`` drew an earlier moment than the log's last,
    without a word (a review). A log without a footer (its writer killed) has no summary to check.
    """
    p = log_path(path)
    size = p.stat().st_size
    tail = _FOOTER.size + len(MAGIC)
    if size < len(MAGIC) + tail:
        return ""
    with p.open("rb") as f:
        f.seek(size - tail)
        footer = f.read(tail)
        opcode, length, start, _, crc = _FOOTER.unpack(footer[:_FOOTER.size])
        if opcode != 0x02 or length != _FOOTER.size - 9 or footer[_FOOTER.size:] != MAGIC or not start or not crc:
            return ""  # no footer, no summary, or a writer that left the CRC out (0: not computed)
        if not len(MAGIC) <= start <= size - tail:
            return f"its footer puts the summary at byte {start}, outside the file"
        f.seek(start)
        got = zlib.crc32(f.read(size - len(MAGIC) - 4 - start))  # up to the footer's CRC itself
    return "" if got == crc else f"the summary, its index, fails its CRC: {got:#010x} where the footer says {crc:#010x}"


def ends_finished(path: str | Path) -> bool:
    """Whether the log ends as a finished one does: with the magic bytes after its footer.

    A quick look, no record read; :func:`read_log` says what a log without them holds.
    """
    with log_path(path).open("rb") as f:
        f.seek(max(0, f.seek(0, 2) - len(MAGIC)))
        return f.read() == MAGIC


def being_written(path: str | Path) -> bool:
    """Whether a writer holds the log's lock now: a run is still writing it (its end is not a kill's).

    The writer (:class:`shared.recording.direct_file.DirectFile`) holds an exclusive ``flock`` while the file is open;
    a shared one is asked for without waiting and let go at once. Read before, a live log said TRUNCATED and
    ``foresight log compress`` of it NOT IDENTICAL (a review). False where the file system takes no lock.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # no locks on this file system: nothing to tell by
        return False
    finally:
        os.close(fd)  # and the lock with it
    return False


class _Bounded:
    """A file whose reads never ask for more than the bytes it has left.

    A damaged length inside a record (an attachment's, say) then reads to the end of the file and fails
    there, instead of allocating exabytes.
    """

    def __init__(self, f: io.BufferedReader, size: int) -> None:
        self._f, self._left = f, size

    def read(self, n: int = -1) -> bytes:
        data = self._f.read(self._left if n is None or n < 0 else min(n, self._left))
        self._left -= len(data)
        return data


def log_path(path: str | Path) -> Path:
    """The log a path names: the path itself, or the one ``.mcap`` under a directory (``runs/demo/latest``).

    A directory with none or several under it stays a directory (:func:`open_records` says which logs it holds).
    """
    p = Path(path)
    if p.is_dir() and len(logs := sorted(p.rglob("*.mcap"))) == 1:
        return logs[0]
    return p


@contextmanager
def open_records(path: str | Path) -> Iterator[StreamReader]:
    """The records of an MCAP file, read in file order with CRCs checked, for every reader of the logs.

    A directory with one log under it (a demo run's, ``runs/demo/latest``) is that log.

    Raises:
        UserError: The path is missing, a directory with no log or several under it, not a regular file (a pipe),
            empty, or does not start with the MCAP magic.
    """
    p = log_path(path)
    if p.is_dir():
        logs = sorted(p.rglob("*.mcap"))
        listed = ", ".join(str(f) for f in logs[:6]) + (f" and {len(logs) - 6} more" if len(logs) > 6 else "")
        none = (", with no .mcap file under it (yet: runs/demo/latest names a demo run from its start, before its "
                "executor writes the log)")
        raise UserError(f"log file {str(p)!r} is a directory" + (f"; the logs under it: {listed}" if logs else none))
    if not p.exists():
        raise UserError(f"log file {str(p)!r} not found")
    if not p.is_file():  # a pipe (process substitution) cannot be read twice or sought: the readers need both
        raise UserError(f"log file {str(p)!r} is not a regular file (a pipe?): copy it to a file first")
    size = p.stat().st_size
    with p.open("rb") as f:
        head = f.read(len(MAGIC))
        if head != MAGIC:
            raise UserError(f"{p}: not an MCAP file ({'empty' if not size else 'no MCAP magic at its start'})")
        f.seek(0, os.SEEK_SET)
        yield StreamReader(typing.cast(typing.IO[bytes], _Bounded(f, size)), validate_crcs=True,
                           record_size_limit=1 << 31)


@dataclass
class LogChannel:
    """One channel of the log and what was read of it."""

    id: int
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_size: int
    count: int = 0
    first_time: int | None = None
    last_time: int | None = None


@dataclass
class LogMessage:
    """One message: its channel's topic, times (ns) and raw payload."""

    topic: str
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class LogFile:
    """What :func:`read_log` found in an MCAP file.

    Attributes:
        complete: True when the footer was read (the writer finished the file) and its summary is intact.
        error: Why reading stopped early (truncated or damaged file), or why the summary is not to be trusted, else "".
        summary_damaged: The footer was read and every record before it, but the summary's CRC does not hold
            (:func:`summary_damage`): the messages are all here, the index is not to be used.
        being_written: A run held the file's lock when it was read (:func:`being_written`): it ends at the last
            whole chunk so far, not where a killed writer left it.
        messages: The kept messages in file order (see ``keep`` of :func:`read_log`).
    """

    path: str
    size: int
    profile: str = ""
    library: str = ""
    channels: dict[int, LogChannel] = field(default_factory=dict)
    messages: list[LogMessage] = field(default_factory=list)
    attachments: dict[str, bytes] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False
    error: str = ""
    summary_damaged: bool = False
    being_written: bool = False

    @property
    def state(self) -> str:
        """How every tool names a log's state.

        ``complete``, ``STILL BEING WRITTEN (...)`` (a run holds it), ``DAMAGED (<its summary>)`` or
        ``TRUNCATED (<why>)``.
        """
        if self.complete:
            return "complete"
        if self.being_written:
            return "STILL BEING WRITTEN (a run holds its lock: read up to its last whole chunk so far)"
        return f"DAMAGED ({self.error})" if self.summary_damaged else f"TRUNCATED ({self.error or 'no footer'})"

    @property
    def message_count(self) -> int:
        """Messages read on all channels."""
        return sum(c.count for c in self.channels.values())

    def topic_messages(self, topic: str) -> list[LogMessage]:
        """The kept messages of one topic."""
        return [m for m in self.messages if m.topic == topic]


def read_log(path: str | Path, keep: Callable[[LogChannel], bool] | None = None) -> LogFile:
    """Read an MCAP file record by record, tolerating a truncated end.

    Args:
        path: The file.
        keep: Keep the payloads of the channels for which it returns True (default: none; counts only).

    Raises:
        UserError: If the file is missing or not an MCAP file at all.
    """
    p = Path(path)
    schemas: dict[int, Schema] = {}
    footer = False
    with open_records(p) as reader:
        out = LogFile(str(p), p.stat().st_size, being_written=being_written(log_path(p)))
        try:
            for rec in reader.records:
                if isinstance(rec, Header):
                    out.profile, out.library = rec.profile, rec.library
                elif isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    if rec.id not in out.channels:
                        sc = schemas.get(rec.schema_id)
                        out.channels[rec.id] = LogChannel(rec.id, rec.topic, rec.message_encoding,
                                                          sc.name if sc else "", sc.encoding if sc else "",
                                                          len(sc.data) if sc else 0)
                elif isinstance(rec, Message):
                    ch = out.channels.get(rec.channel_id)
                    if ch is None:
                        raise McapError(f"message on unknown channel {rec.channel_id}")
                    ch.count += 1
                    ch.first_time = rec.log_time if ch.first_time is None else min(ch.first_time, rec.log_time)
                    ch.last_time = rec.log_time if ch.last_time is None else max(ch.last_time, rec.log_time)
                    if keep is not None and keep(ch):
                        out.messages.append(LogMessage(ch.topic, rec.log_time, rec.publish_time, bytes(rec.data)))
                elif isinstance(rec, Attachment):
                    out.attachments[rec.name] = bytes(rec.data)
                elif isinstance(rec, Metadata):
                    out.metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Footer):
                    footer = True
            out.complete = footer  # and the closing magic after it: a copy cut within it is not complete
            if footer and (damage := summary_damage(p)):
                out.complete, out.summary_damaged, out.error = False, True, damage
        except DAMAGED as exc:
            out.error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    return out


def iter_messages(path: str | Path) -> Iterator[LogMessage]:
    """Every message of a log in file order, one at a time (what :func:`read_log` keeps, without holding it all).

    Stops where the file is damaged or ends, as :func:`read_log` does (its ``error`` says why).

    Raises:
        UserError: If the file is missing or not an MCAP file at all.
    """
    topics: dict[int, str] = {}
    with open_records(Path(path)) as reader:
        try:
            for rec in reader.records:
                if isinstance(rec, Channel):
                    topics.setdefault(rec.id, rec.topic)
                elif isinstance(rec, Message):
                    if rec.channel_id not in topics:
                        raise McapError(f"message on unknown channel {rec.channel_id}")
                    yield LogMessage(topics[rec.channel_id], rec.log_time, rec.publish_time, bytes(rec.data))
        except DAMAGED:
            return
