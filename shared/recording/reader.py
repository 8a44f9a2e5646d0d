"""The MCAP reader: a run's log read record by record, tolerating a truncated end.

:func:`read_log` goes through the file with mcap's stream reader, so it needs no summary section:
a file whose writer was killed is read up to its last complete chunk (``LogFile.complete`` is then
False and ``LogFile.error`` says why reading stopped); a finished one with a damaged chunk is read past it
(:mod:`shared.recording.recovery`; ``LogFile.damage`` says what was skipped). The records it understands are the ones
:mod:`shared.recording.writer` writes: header, schemas, channels, messages, attachments, metadata.
"""

from __future__ import annotations

import fcntl
import os
import struct
import typing
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from shared.recording.recovery import DAMAGED, Bounded, Records, describe
from shared.runtime import UserError

__all__ = ["LogChannel", "LogMessage", "LogFile", "read_log", "iter_messages", "open_records", "log_path", "DAMAGED",
           "MAGIC", "summary_damage", "being_written", "ends_finished", "SOURCE_METADATA", "STILL_WRITTEN",
           "checked_records"]

SOURCE_METADATA = "foresight.compress"
"""Metadata record of a copy made from a truncated or damaged log (``foresight log compress``): ``source``,
``source_complete`` = "false" and ``source_error`` (``foresight log info`` shows it: the copy is whole, what it was
copied from was not)."""

STILL_WRITTEN = "still being written when copied: up to its last whole chunk then"
"""``source_error`` of a copy of a log a run was still writing."""

MAGIC = b"\x89MCAP0\r\n"
"""The first (and last) eight bytes of an MCAP file."""

# DAMAGED (shared.recording.recovery): what reading a damaged MCAP raises. Every reader of the logs reads through
# open_records (validate_crcs=True, no read past the file's end); read_log and iter_messages through checked_records,
# which skips a damaged chunk of a finished log and stops at any other damage: what came before stands.


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
    with _opened(path) as (reader, _):
        yield reader


@contextmanager
def checked_records(path: str | Path) -> Iterator[Records]:
    """The records of a log as :func:`open_records` reads them, past a damaged chunk where it can be skipped.

    A chunk failing its CRC in a finished log whose summary is intact is skipped and counted
    (:class:`~shared.recording.recovery.Records`); elsewhere reading stops there. The readers of messages
    (:func:`read_log`, :func:`iter_messages`, ``foresight log compress``) read through it, so they agree.

    Raises:
        UserError: As :func:`open_records`, and a file that ends (or is damaged) before its header does.
    """
    p = log_path(path)
    with _opened(p, emit_chunks=True) as (reader, source):
        skip = ends_finished(p) and not summary_damage(p)
        try:
            yield Records(reader, source, skip, _schemas_and_channels(p) if skip else None)
        except UserError as exc:  # raised by Records, which has no path
            raise UserError(f"{p}: {exc}") from None


def _schemas_and_channels(p: Path) -> list[typing.Any]:
    """The schemas and channels of a finished log's summary (none where it cannot be read)."""
    from mcap.reader import SeekingReader

    try:
        with p.open("rb") as f:
            summary = SeekingReader(f, validate_crcs=True).get_summary()
    except DAMAGED:
        return []
    return [] if summary is None else [*summary.schemas.values(), *summary.channels.values()]


@contextmanager
def _opened(path: str | Path, emit_chunks: bool = False) -> Iterator[tuple[StreamReader, Bounded]]:
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
        source = Bounded(f, size)
        yield StreamReader(typing.cast(typing.IO[bytes], source), validate_crcs=True, emit_chunks=emit_chunks,
                           record_size_limit=1 << 31), source


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
        complete: True when the footer was read (the writer finished the file), its summary is intact and nothing in
            it is damaged.
        error: Why reading stopped early (truncated or damaged file), why the summary is not to be trusted, or what
            is damaged, else "".
        damage: What is damaged in the file (chunks skipped, the chunk reading stopped at, an attachment or the
            metadata), else "": the log is then DAMAGED, not TRUNCATED, even while a run writes it.
        chunks_skipped: Chunks of a finished log that failed their CRC and were skipped (the others were read).
        messages_lost: The messages in them (from their message indexes; None: not known).
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
    damage: str = ""
    chunks_skipped: int = 0
    messages_lost: int | None = 0

    @property
    def state(self) -> str:
        """How every tool names a log's state.

        ``complete``, ``DAMAGED (<what>)`` (a chunk, an attachment, the metadata or the summary; a damaged chunk is
        named even while a run holds the log), ``STILL BEING WRITTEN (...)`` (a run holds it) or ``TRUNCATED (<why>)``.
        """
        if self.complete:
            return "complete"
        if self.damage:
            live = "; a run holds its lock" if self.being_written else ""
            return f"DAMAGED ({self.damage}{live})"
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
    with checked_records(p) as records:
        out = LogFile(str(p), p.stat().st_size, being_written=being_written(log_path(p)))
        try:
            for rec in records:
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
        except DAMAGED as exc:
            out.error = describe(exc)
        out.damage, out.chunks_skipped, out.messages_lost = records.damage, records.skipped, records.lost
        out.complete = records.ended and not records.damage  # and the closing magic after the footer: a copy cut
        if records.ended and (damage := summary_damage(p)):  # within it is not complete
            out.complete, out.summary_damaged, out.error = False, True, damage
        elif records.damage:  # and where reading stopped after it, if it did
            then = f"; then stopped: {out.error}" if out.error and out.error not in records.damage else ""
            out.error = records.damage + then
    return out


def iter_messages(path: str | Path) -> Iterator[LogMessage]:
    """Every message of a log in file order, one at a time (what :func:`read_log` keeps, without holding it all).

    Skips a damaged chunk and stops where the file is damaged otherwise or ends, as :func:`read_log` does (its
    ``error`` says why).

    Raises:
        UserError: If the file is missing or not an MCAP file at all.
    """
    topics: dict[int, str] = {}
    with checked_records(Path(path)) as records:
        try:
            for rec in records:
                if isinstance(rec, Channel):
                    topics.setdefault(rec.id, rec.topic)
                elif isinstance(rec, Message):
                    if rec.channel_id not in topics:
                        raise McapError(f"message on unknown channel {rec.channel_id}")
                    yield LogMessage(topics[rec.channel_id], rec.log_time, rec.publish_time, bytes(rec.data))
        except DAMAGED:
            return
