"""The MCAP writer of a run: every message on every key under the prefix, plus Foxglove scene channels.

Layout (see docs/executor.md; the channels' schemas are in :mod:`shared.recording.schemas`):

* one channel per Zenoh key expression (topic = the key, e.g. ``foresight/planner/plan``), message
  encoding ``msgpack`` (the raw payload, byte for byte), schema = the message type's JSON Schema
  (encoding ``jsonschema``, :func:`shared.recording.schemas.message_json_schema`); only payloads
  that decode are written there;
* ``/foresight/rejected`` (JSON): one record per payload that was refused (failed to decode, or its
  values or order were refused on receipt: key, reason, error, size, the first bytes in hex); such a
  payload never goes on its key's channel. Reject counts per key (``foresight.rejects``) and per key
  and reason (``foresight.rejects.reasons``, entries ``"<key> <reason>"``) are metadata records
  written when the file is closed;
* the scene channels (:data:`shared.foxglove.stream.SCHEMAS`: Foxglove's well-known messages encoded as
  protobuf by ``foxglove-sdk``, each channel's schema the ``FileDescriptorSet`` the SDK carries; the
  posterior and the costs as JSON), built by a :class:`shared.foxglove.stream.SceneStream`, every entity
  and transform stamped with the record's log time (the receive time), so a log has one time base for
  Foxglove even in lock-step, where the messages themselves carry simulated time;
* attachment ``scene.toml`` (the scene the run used) and metadata ``foresight.run`` (the config).

Chunks are compressed with zstd by default (``compression``; lz4 or none on request). The file is
written in chunks straight to the operating system (no user-space buffer) and the open
chunk is flushed every ``flush_period_s``, by a thread of its own when no message comes to do it (a run
waiting for its peers); if the process is killed, everything up to the last complete chunk stays readable
(with a non-seeking reader, see :func:`shared.recording.reader.read_log`). Once the file has ended (the OS
refused bytes past what :mod:`shared.recording.direct_file` holds), every later message raises at once
instead of growing the writer's index of a chunk that will never be written. At the close, bytes still held are
retried for :data:`CLOSE_RETRY_S` (space may come back); what is still refused then is lost, and the close says how
many messages in one line (``INCOMPLETE: N of M messages written``; ``McapLog.ledger``), counted per chunk. A message
given after the close is not written: counted (``McapLog.dropped_after_close``) and said once. The log time of a
message is read under the writer's lock, so a file's raw messages are in log-time order whatever thread writes them.
"""

from __future__ import annotations

import errno
import io
import json
import logging
import os
import threading
import time
import typing
from collections.abc import Callable
from typing import Any

from mcap.writer import CompressionType, Writer

from shared.atomic_file import make_parent
from shared.foxglove.scene import SceneBuilder
from shared.foxglove.stream import SceneStream, VizMessage
from shared.protocol import MESSAGE_TYPES, Keys, Message, ProtocolError, decode

from .background import BackgroundWorker
from .direct_file import DirectFile
from .ledger import Ledger
from .schemas import PROFILE, REJECTED_SCHEMA, REJECTED_TOPIC, message_json_schema

__all__ = ["McapLog", "COMPRESSION", "CLOSE_RETRY_S"]

COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
"""Chunk compressions by name (the ``mcap`` library compresses with ``zstandard`` and ``lz4``)."""

MAX_NS = 2 ** 64 - 1
"""The latest time an MCAP record holds (uint64 nanoseconds: the year 2554)."""

CLOSE_RETRY_S = 3.0
"""Seconds a close retries the bytes a full disk refused (within a stopping service's grace, with its other waits)."""

log = logging.getLogger(__name__)


class McapLog:
    """Thread-safe MCAP writer of Foresight messages (call :meth:`on_sample` from any thread).

    Args:
        path: Output file (parent directories are created).
        keys: The key expressions of the run (its prefix).
        builder: Builds the scene channels (None: none).
        viz_period_s: Smallest time (message stamps) between two scene updates of the robot, the
            human or the occupancy (plans and posteriors are drawn every time).
        chunk_size: Chunk size in bytes.
        flush_period_s: Longest time an incomplete chunk stays in memory (finite; 0: each message is flushed).
        scene_text: The scene file's text, attached as ``scene.toml``.
        run_metadata: String map written as metadata ``foresight.run``.
        clock: Log-time source in nanoseconds (default ``time.time_ns``).
        viz_thread: Build the scene updates of received messages on a background thread
            (:class:`~shared.recording.background.BackgroundWorker`), so that a caller logging from its
            receive path never waits for them (the robot's and the paths' forward kinematics); updates are stamped
            with the message's receive time all the same, and one that finds ``viz_pending`` waiting is
            dropped (counted, metadata ``foresight.viz``). False: built in :meth:`log_message`.
        viz_pending: Foxglove updates that may wait for the background thread.
        on_viz: Also called with each scene message written (e.g. a live server's ``log``), outside the lock.
        compression: Chunk compression, ``"zstd"``, ``"lz4"`` or ``"none"``. A chunk is compressed as a
            whole when it is closed, so a killed writer's file still reads back up to its last chunk.
    """

    def __init__(self, path: str | os.PathLike[str], keys: Keys, builder: SceneBuilder | None = None,
                 viz_period_s: float = 0.2, chunk_size: int = 256 * 1024, flush_period_s: float = 1.0,
                 scene_text: str | None = None, run_metadata: dict[str, str] | None = None,
                 clock: Callable[[], int] = time.time_ns, viz_thread: bool = True, viz_pending: int = 16,
                 compression: str = "zstd", on_viz: Callable[[VizMessage], None] | None = None) -> None:
        if compression not in COMPRESSION:
            raise ValueError(f"MCAP compression must be one of {', '.join(COMPRESSION)}, got {compression!r}")
        if not 0 <= flush_period_s <= threading.TIMEOUT_MAX:
            raise ValueError(f"MCAP flush period must be a finite number of seconds >= 0, got {flush_period_s}")
        self.path = make_parent(path)  # a file where a directory is needed: named (mkdir said "File exists")
        self.keys = keys
        self._stream = SceneStream(builder, viz_period_s) if builder is not None else None
        self._on_viz = on_viz
        self.flush_period_s = flush_period_s
        self._clock = clock
        self._lock = threading.RLock()
        self._file = DirectFile(self.path)
        self._writer = Writer(typing.cast(io.BufferedWriter, self._file), chunk_size=chunk_size,
                              compression=COMPRESSION[compression], enable_data_crcs=True)  # damage outside chunks
        self._writer.start(profile=PROFILE, library="foresight executor")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._last_flush = time.monotonic()
        self._closed = False
        self._removal_said = False
        self.ledger = Ledger(self._file, self._writer)  # which messages are on the disk
        self.dropped_after_close = 0
        self.counts: dict[str, int] = {}
        self.rejects: dict[str, int] = {}
        self.reject_reasons: dict[str, int] = {}
        self.viz_errors = 0
        self.live_errors = 0
        self._expected = keys.data_keys()
        if scene_text is not None:
            now = self._clock()
            self._writer.add_attachment(now, now, "scene.toml", "application/toml", scene_text.encode())
        if run_metadata:
            self._writer.add_metadata("foresight.run", {k: str(v) for k, v in run_metadata.items()})
        if self._stream is not None:  # stamped and logged at the same (receive-time) clock as every later update
            for m in self._stream.static(self._clock()):
                self.write_viz(m)
        with self.ledger.writing():
            self._writer.flush()
        self._viz = (BackgroundWorker(self._visualise_item, "mcap-foxglove", viz_pending)
                     if builder is not None and viz_thread else None)
        self._flush_errors = 0
        self._stop_flushing = threading.Event()
        self._flusher = None  # with a period of 0 every message flushes: no quiet spell holds one back
        if flush_period_s > 0:
            self._flusher = threading.Thread(target=self._flush_periodically, name="mcap-flush", daemon=True)
            self._flusher.start()

    # -- channels ------------------------------------------------------------------------------

    def _schema_id(self, name: str, schema: dict[str, Any]) -> int:
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(
                name=name, encoding="jsonschema", data=json.dumps(schema, separators=(",", ":")).encode())
        return self._schemas[name]

    def _channel_id(self, topic: str, schema_name: str, schema: dict[str, Any], encoding: str) -> int:
        if topic not in self._channels:
            sid = self._schema_id(schema_name, schema)
            self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding=encoding,
                                                                  schema_id=sid)
        return self._channels[topic]

    def _add(self, channel: int, topic: str, data: bytes, log_time: int, publish_time: int) -> None:
        if (failed := self._file.failed) is not None:  # the file has ended: the writer would only grow its index
            self.ledger.refused += 1
            raise OSError(failed.errno, f"{self.path}: the log has ended ({failed.strerror}); message on {topic} "
                          "not written")
        # checked before the writer takes it: a field that does not pack failed half-way through the record, and the
        # open chunk then held a broken message (a stamp of 1e11 s: the file read as complete, with garbage in it)
        for name, t in (("log", log_time), ("publish", publish_time)):
            if not (isinstance(t, int) and 0 <= t <= MAX_NS):
                raise ValueError(f"{self.path}: message on {topic} not written: its {name} time {t!r} ns is not an "
                                 f"MCAP time (an integer 0 .. {MAX_NS}, until the year 2554)")
        with self.ledger.writing():  # a chunk filled up and written: this message is the last in it
            try:
                self._writer.add_message(channel_id=channel, log_time=log_time, data=data, publish_time=publish_time,
                                         sequence=self.counts.get(topic, 0) & 0xFFFFFFFF)  # uint32: it wraps
            finally:  # taken even when its chunk's bytes ended the file: they are held
                self.counts[topic] = self.counts.get(topic, 0) + 1
                self.ledger.total += 1
        self.flush_if_due()

    def _late(self, topic: str) -> None:
        """A message given after the close: not written, counted, said once."""
        self.dropped_after_close += 1
        if self.dropped_after_close == 1:
            log.warning("mcap log %s: a message on %s came after the log was closed: not written (counted, "
                        "dropped_after_close)", self.path, topic)


    def write_rejected(self, obj: dict[str, Any], log_time: int | None = None) -> None:
        """Write a record on the rejects channel (JSON)."""
        data = json.dumps(obj, separators=(",", ":")).encode()
        with self._lock:
            if self._closed:
                return self._late(REJECTED_TOPIC)
            cid = self._channel_id(REJECTED_TOPIC, "foresight.Rejected", REJECTED_SCHEMA, "json")
            t = self._clock() if log_time is None else log_time
            self._add(cid, REJECTED_TOPIC, data, t, t)

    def write_viz(self, m: VizMessage) -> None:
        """Write an encoded scene message on its channel (registered with its schema on first use)."""
        with self._lock:
            if self._closed:
                return self._late(m.topic)
            if m.topic not in self._channels:
                s = m.schema
                if s.name not in self._schemas:
                    self._schemas[s.name] = self._writer.register_schema(name=s.name, encoding=s.encoding,
                                                                         data=s.data)
                self._channels[m.topic] = self._writer.register_channel(
                    topic=m.topic, message_encoding=s.message_encoding, schema_id=self._schemas[s.name])
            self._add(self._channels[m.topic], m.topic, m.data, m.log_time, m.log_time)
        if self._on_viz is not None:
            try:
                self._on_viz(m)
            except Exception:  # the live server's trouble must never cost the log
                self.live_errors += 1
                if self.live_errors == 1 or self.live_errors % 100 == 0:
                    log.exception("mcap log: passing a scene message on (on_viz) failed (%d so far)",
                                  self.live_errors)

    def write_ros2(self, topic: str, msgtype: str, data: bytes, log_time: int | None = None) -> None:
        """Write a ROS 2 message as sent or received (CDR, schema ``ros2msg``: its definition from ``rosbags``)."""
        with self._lock:
            if self._closed:
                return self._late(topic)
            if topic not in self._channels:
                from rosbags.typesys import Stores, get_typestore

                msgdef, _ = get_typestore(Stores.ROS2_JAZZY).generate_msgdef(msgtype, ros_version=2)
                sid = self._writer.register_schema(name=msgtype, encoding="ros2msg", data=msgdef.encode())
                self._channels[topic] = self._writer.register_channel(topic, "cdr", sid)
            t = self._clock() if log_time is None else log_time
            self._add(self._channels[topic], topic, data, t, t)

    # -- samples -------------------------------------------------------------------------------

    def on_sample(self, key: str, payload: bytes) -> Message | None:
        """Decode and log one sample received on ``key``; returns the message (None if rejected).

        Its log time is read as it is written (under the lock): read before, a thread that waited for the lock wrote
        a time older than the record before it.
        """
        try:
            msg: Message = decode(payload, self._expected.get(key))
        except ProtocolError as exc:
            self.reject(key, payload, str(exc), reason=exc.reason)
            return None
        self.log_message(key, payload, msg)
        return msg

    def log_message(self, key: str, payload: bytes, msg: Message, log_time: int | None = None) -> None:
        """Log a payload already decoded (and so validated) as ``msg`` on ``key``'s channel (``log_time``: now)."""
        stamp = float(getattr(msg, "stamp", -1.0))
        with self._lock:
            if self._closed:
                return self._late(key)
            log_time = self._clock() if log_time is None else log_time  # under the lock: the file in log-time order
            publish = int(min(stamp * 1e9, 2.0 ** 64)) if stamp >= 0 else log_time  # past MCAP's: refused by _add
            cid = self._channels.get(key)
            if cid is None:  # the schema is built once per channel, not per message
                cid = self._channel_id(key, f"foresight.{msg.TYPE}", message_json_schema(MESSAGE_TYPES[msg.TYPE]),
                                       "msgpack")
            self._add(cid, key, bytes(payload), log_time, publish)
        if self._stream is None or self._expected.get(key) is not type(msg):
            return  # drawn from its own key only: a plan put elsewhere under the prefix is logged, not the robot's
        with self._lock:
            topic = self._stream.due(msg)
            if topic is None:
                return
            # a dropped update does not count as drawn: the next message of its kind may draw instead
            if self._viz is None or self._viz.submit((msg, log_time)):
                self._stream.mark(topic, msg)
        if self._viz is None:
            self._visualise(msg, log_time)

    def reject(self, key: str, payload: bytes, error: str, log_time: int | None = None, quiet: bool = False,
               reason: str = "malformed") -> None:
        """Count a refused payload and write it to the rejects channel (never to the key's channel).

        Args:
            key: Key it arrived on.
            payload: The bytes.
            error: Why (the decoder's or the validation's message).
            log_time: Receive time (ns; default now).
            quiet: Do not log a warning (the caller already did).
            reason: The category (``shared.protocol.REASONS``).
        """
        with self._lock:
            self.rejects[key] = self.rejects.get(key, 0) + 1
            self.reject_reasons[f"{key} {reason}"] = self.reject_reasons.get(f"{key} {reason}", 0) + 1
            n = self.rejects[key]
        if not quiet and (n == 1 or n % 100 == 0):
            log.warning("mcap log: rejected payload #%d on %s (%s): %s", n, key, reason, error)
        self.write_rejected({"key": key, "reason": reason, "error": error[:500], "size": len(payload),
                                         "head_hex": bytes(payload[:64]).hex()}, log_time)

    def _visualise_item(self, item: tuple[Message, int]) -> None:
        self._visualise(*item)

    def _visualise(self, msg: Message, log_time: int) -> None:
        assert self._stream is not None
        try:
            for m in self._stream.draw(msg, log_time):
                self.write_viz(m)
        except Exception:  # a visualisation bug must never cost the raw log
            self.viz_errors += 1
            if self.viz_errors == 1 or self.viz_errors % 100 == 0:
                log.exception("mcap log: scene update for %s failed (%d so far)", msg.TYPE, self.viz_errors)

    # -- lifecycle -----------------------------------------------------------------------------

    def _flush_periodically(self) -> None:
        """The flushes no message triggers: a chunk waits at most ``flush_period_s`` even in a quiet spell."""
        while not self._stop_flushing.wait(max(0.0, self._last_flush + self.flush_period_s - time.monotonic())):
            try:
                self.flush_if_due()
            except Exception as exc:  # a full disk: the next message's write fails and is counted by its caller
                self._flush_errors += 1
                if self._flush_errors == 1 or self._flush_errors % 100 == 0:
                    log.error("mcap log %s: flushing failed (%d so far): %s", self.path, self._flush_errors, exc)
                self._stop_flushing.wait(self.flush_period_s)

    def flush_if_due(self) -> None:
        """Write the open chunk if it is older than ``flush_period_s`` (call it periodically)."""
        if time.monotonic() - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Write the open chunk to the file now (nothing once a full disk has ended the file)."""
        with self._lock:
            if not self._closed and self._file.failed is None:
                with self.ledger.writing():
                    self._writer.flush()
                self._last_flush = time.monotonic()
                if not self._removal_said and self._file.removed:
                    self._removal_said = True
                    log.error("mcap log %s: the file was deleted while it is written (or its directory); what it "
                              "holds is lost when the run ends", self.path)

    def close(self) -> None:
        """Finish the queued scene updates, write the reject counts, the summary and the footer; idempotent."""
        if self._viz is not None:
            # outside the lock: the updates still queued take it to write. Both waits are bounded well within a
            # stopping process's grace (shared.runtime.SHUTDOWN_GRACE_S), so the footer is written before it ends
            self._viz.close(timeout_s=5.0)
        self._stop_flushing.set()
        if self._flusher is not None and self._flusher is not threading.current_thread():
            self._flusher.join(2.0)  # a flush holds the lock at most as long as a write
        with self._lock:
            if self._closed:
                return
            self._closed = True  # first: a close that fails (a full disk) is not repeated over what it half-wrote
            error: OSError | None = None
            try:
                if self._stream is not None:  # lock-step's too (built in the callback: none dropped, none left)
                    pending = self._viz.pending if self._viz is not None else 0  # queued past the worker's close
                    viz = {"dropped": self.viz_dropped, "unfinished": pending, "errors": self.viz_errors}
                    self._writer.add_metadata("foresight.viz", {k: str(v) for k, v in viz.items()})
                self._writer.add_metadata("foresight.rejects", {k: str(v) for k, v in sorted(self.rejects.items())})
                self._writer.add_metadata("foresight.rejects.reasons",
                                          {k: str(v) for k, v in sorted(self.reject_reasons.items())})
                with self.ledger.writing():
                    self._writer.finish()
            except OSError as exc:  # the file had ended (a full disk): what it holds is still written below
                error = exc
        try:  # outside the lock (closed: no writer touches the file): a late message is not kept waiting by the retry
            if held := self._file.drain(CLOSE_RETRY_S):  # space may come back within a few seconds
                error = error or OSError(errno.ENOSPC, f"{held} bytes refused for {CLOSE_RETRY_S:g} s")
            else:
                self._file.fsync()
        except OSError as exc:
            error = error or exc
        finally:
            removed = self._file.removed
            self._file.close()
        if (incomplete := self.ledger.closed(self.path, removed, error)) is not None:
            log.error("mcap log %s", incomplete.strerror)  # said here, once, whoever closes (and raised to them)
            raise incomplete
        log.info("mcap log: wrote %s (%d messages on %d channels, %d rejected, %d scene updates dropped)",
                 self.path, sum(self.counts.values()), len(self.counts), sum(self.rejects.values()), self.viz_dropped)

    @property
    def viz_dropped(self) -> int:
        """Scene updates dropped because ``viz_pending`` were already waiting for the background thread."""
        return self._viz.dropped if self._viz is not None else 0

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
