"""``foresight log compress IN OUT``: rewrite an MCAP log with compressed (or uncompressed) chunks.

Every record that carries data is copied in file order - schemas, channels, messages (topic, log and
publish time, payload byte for byte), attachments and metadata - into a new file whose chunks are
compressed with zstd (default), lz4 or not at all; then both files are read back and compared
message for message. A truncated input is copied up to its last complete chunk (and said so); so is a log still
being written (a run holds its lock), whose copy is compared with the messages it had when copied. A damaged input
is copied without what its damage took (a chunk failing its CRC skipped, a damaged attachment), the copy says so,
and the command fails (status 1): the copy lacks part of the source.
Logs written before the executor compressed its chunks (issue 24) shrink about 12x this way.
"""

from __future__ import annotations

import io
import itertools
import os
import typing
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import Writer

from shared.atomic_file import atomic_write
from shared.recording.reader import (
    DAMAGED,
    MAGIC,
    SOURCE_METADATA,
    STILL_WRITTEN,
    being_written,
    checked_records,
    iter_messages,
    log_path,
    read_log,
)
from shared.recording.recovery import Records, describe
from shared.recording.writer import COMPRESSION
from shared.runtime import UserError

__all__ = ["CompressResult", "compress_log", "same_messages", "SOURCE_METADATA"]



@dataclass
class CompressResult:
    """What :func:`compress_log` did: sizes in bytes, messages copied, and whether the input was complete."""

    size_in: int
    size_out: int
    messages: int
    input_complete: bool
    identical: bool
    input_error: str = ""
    being_written: bool = False
    input_damage: str = ""

    @property
    def ok(self) -> bool:
        """The copy holds what the input does: identical, and nothing of the input lost to damage."""
        return self.identical and not self.input_damage

    def line(self, src: Path, dst: Path) -> str:
        """One line for the user."""
        ratio = self.size_in / max(self.size_out, 1)
        state = "" if self.input_complete else (f" (the input is truncated ({self.input_error or 'no footer'}): copied "
                                                "up to its last complete chunk, and the copy says so)")
        if self.input_damage:  # "read back identical" of a copy that lacks part of the input (a review)
            state = (f" (the input is DAMAGED ({self.input_damage}): the copy lacks what the damage took, and says "
                     "so)")
        same = "identical" if self.identical else "NOT IDENTICAL"
        size = f"{ratio:.1f}x smaller" if ratio >= 1 else f"{1 / ratio:.1f}x larger"
        if self.being_written and not self.input_damage:
            return (f"{src} is still being written (a run holds its lock): {self.messages} messages copied so far, up "
                    f"to its last whole chunk, -> {dst} ({self.size_out / 1e6:.2f} MB), compared {same} with the "
                    f"log's first {self.messages}; the copy says so: compress the log again once its run has ended")
        return (f"{src} ({self.size_in / 1e6:.2f} MB) -> {dst} ({self.size_out / 1e6:.2f} MB, {size}); "
                f"{self.messages} messages read back {same}{state}")


def compress_log(src: str | Path, dst: str | Path, compression: str = "zstd",
                 chunk_size: int = 1024 * 1024) -> CompressResult:
    """Copy ``src`` to ``dst`` with ``compression`` chunks, then compare the two message for message.

    Raises:
        UserError: If ``src`` is missing or not an MCAP file, ``dst`` is ``src`` or an existing file that is not an
            MCAP file (a typo of the output's name would have replaced it), or the compression is unknown.
    """
    src, dst = log_path(src), Path(dst)
    if compression not in COMPRESSION:
        raise UserError(f"--compression must be one of {', '.join(COMPRESSION)}, got {compression!r}")
    if dst.is_dir():
        raise UserError(f"{dst} is a directory: give the output file's name")
    if dst.exists() and src.exists() and os.path.samefile(src, dst):  # a hard link too: writing it empties the input
        raise UserError("the output must be another file than the input")
    if dst.is_file() and dst.stat().st_size and _head(dst) != MAGIC:  # an empty file holds nothing to lose
        raise UserError(f"{dst} exists and is not an MCAP file: not replaced (remove it, or give another output)")
    with checked_records(src) as records:  # the input checked (an MCAP file) before the output is touched
        live = being_written(src)  # then read up to its size now: the comparison is with what the copy had
        # written beside dst and renamed onto it: a failure (a full disk, Ctrl-C) leaves an existing dst as it was
        with atomic_write(dst) as f_out:
            messages, complete, error = _copy(records, f_out, compression, chunk_size, src, live)
    return CompressResult(src.stat().st_size, dst.stat().st_size, messages, complete,
                          same_messages(src, dst, prefix=live), error, live, records.damage)


def _head(path: Path) -> bytes:
    with path.open("rb") as f:
        return f.read(len(MAGIC))


def _copy(records: Records, f_out: typing.BinaryIO, compression: str, chunk_size: int, src: Path,
          live: bool = False) -> tuple[int, bool, str]:
    """Copy ``records`` into a new MCAP on ``f_out``; returns (messages, input complete, why it ended)."""
    writer = Writer(typing.cast(io.BufferedWriter, f_out), chunk_size=chunk_size, compression=COMPRESSION[compression],
                    enable_data_crcs=True)
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    messages, started, error = 0, False, ""
    try:
        for rec in records:
            if isinstance(rec, Header):
                writer.start(profile=rec.profile, library=rec.library)
                started = True
            elif isinstance(rec, Schema) and rec.id not in schemas:
                schemas[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel) and rec.id not in channels:
                channels[rec.id] = writer.register_channel(rec.topic, rec.message_encoding,
                                                           schemas.get(rec.schema_id, 0), dict(rec.metadata))
            elif isinstance(rec, Message):
                if rec.channel_id not in channels:
                    raise McapError(f"message on unknown channel {rec.channel_id}")
                writer.add_message(channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time, rec.sequence)
                messages += 1
            elif isinstance(rec, Attachment):
                writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
            elif isinstance(rec, Metadata):
                writer.add_metadata(rec.name, dict(rec.metadata))
    except DAMAGED as exc:  # truncated or damaged: what was read is copied, and the copy says so
        error = describe(exc)
    if not started:  # records raise a file that ends (or is damaged) before its header ends
        raise UserError(f"{src}: not an MCAP file (no header)")
    if records.damage:  # named even while a run writes it: a damaged chunk is no run's end
        error = records.damage + (f"; then stopped: {error}" if error and error not in records.damage else "")
    elif live and not records.ended:  # its end is where the run had got to, not damage
        error = STILL_WRITTEN
    if error or not records.ended:
        writer.add_metadata(SOURCE_METADATA, {"source": str(src), "source_complete": "false",
                                              "source_state": "DAMAGED" if records.damage else "TRUNCATED",
                                              "source_error": error or "no footer"})
    writer.finish()
    return messages, records.ended and not error, error


def same_messages(a: str | Path, b: str | Path, prefix: bool = False) -> bool:
    """Whether two logs hold the same messages (topic, encoding, times, payload) in the same order.

    The messages are compared one at a time (memory: a chunk of each), not read into two lists first: that held
    both logs' payloads, 6 GB for an hour of a real-time run.

    Args:
        a: The original.
        b: The copy.
        prefix: ``a`` is still being written (it grew since ``b`` was copied from it): ``b``'s messages are compared
            with ``a``'s first ones, and its channels, attachments and metadata are to be found in ``a``.
    """
    la, lb = read_log(a), read_log(b)  # channels, attachments and metadata; counts only

    def metadata(lf: typing.Any) -> dict[str, dict[str, str]]:  # a copy's note on its source is no difference
        return {k: v for k, v in lf.metadata.items() if k != SOURCE_METADATA}

    def channels(lf: typing.Any) -> list[tuple[str, str, str]]:
        return sorted((c.topic, c.message_encoding, c.schema_name) for c in lf.channels.values())

    end = object()
    if prefix:
        ma, ia = metadata(la), iter_messages(a)
        return (all(la.attachments.get(k) == v for k, v in lb.attachments.items())
                and all(ma.get(k) == v for k, v in metadata(lb).items()) and set(channels(lb)) <= set(channels(la))
                and all(next(ia, end) == y for y in iter_messages(b)))
    if la.attachments != lb.attachments or metadata(la) != metadata(lb) or channels(la) != channels(lb):
        return False
    return all(x == y for x, y in itertools.zip_longest(iter_messages(a), iter_messages(b), fillvalue=end))
