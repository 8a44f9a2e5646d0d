"""The MCAP reader: a run's log read record by record, tolerating a truncated end.

:func:`read_log` goes through the file with mcap's stream reader, so it needs no summary section:
a file whose writer was killed is read up to its last complete chunk (``LogFile.complete`` is then
False and ``LogFile.error`` says why reading stopped). The records it understands are the ones
:mod:`shared.recording.writer` writes: header, schemas, channels, messages, attachments, metadata.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import zstandard
from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from shared.runtime import UserError

__all__ = ["LogChannel", "LogMessage", "LogFile", "read_log", "DAMAGED"]

DAMAGED = (McapError, struct.error, ValueError, EOFError, zstandard.ZstdError, RuntimeError)
"""What reading a damaged MCAP raises: the mcap library's errors, a record cut short (``struct.error``,
``EOFError``), a chunk whose CRC does not match (``CRCValidationError``, a ``ValueError``), and a compressed chunk
that does not decompress (zstandard's ``ZstdError``; lz4 raises ``RuntimeError``). Every reader of the logs reads
with ``validate_crcs=True`` and stops at the first of these: what came before stands."""


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
        complete: True when the footer was read (the writer finished the file).
        error: Why reading stopped early (truncated or damaged file), else "".
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
    if not p.is_file():
        raise UserError(f"log file {str(p)!r} not found")
    out = LogFile(str(p), p.stat().st_size)
    schemas: dict[int, Schema] = {}
    with p.open("rb") as f:
        reader = StreamReader(f, validate_crcs=True, record_size_limit=1 << 31)
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
                    out.complete = True
        except DAMAGED as exc:
            if not out.channels and not out.profile and not out.complete:
                if isinstance(exc, McapError) and "magic" in str(exc).lower():
                    raise UserError(f"{p}: not an MCAP file ({exc})") from None
            out.error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    return out
