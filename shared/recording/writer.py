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
* Foxglove channels (JSON, well-known schemas), built by a :class:`FoxgloveScene` (the conversion is
  :class:`shared.recording.foxglove.SceneBuilder`), every entity and transform stamped with the
  record's log time (the receive time), so a log has one time base for Foxglove even in lock-step,
  where the messages themselves carry simulated time;
* attachment ``scene.toml`` (the scene the run used) and metadata ``foresight.run`` (the config).

Chunks are compressed with zstd by default (``compression``; lz4 or none on request). The file is
written in chunks straight to the operating system (no user-space buffer) and the open
chunk is flushed every ``flush_period_s``; if the process is killed, everything up to the last
complete chunk stays readable (with a non-seeking reader, see :func:`shared.recording.reader.read_log`).
"""

from __future__ import annotations

import io
import json
import logging
import os
import threading
import time
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from mcap.writer import CompressionType, Writer

from shared.protocol import (
    MESSAGE_TYPES,
    HumanPose,
    Keys,
    Message,
    OccupancyGrid,
    Plan,
    ProtocolError,
    RobotState,
    decode,
)

from .background import BackgroundWorker
from .direct_file import DirectFile
from .json_slices import dumps_sliced
from .schemas import PROFILE, REJECTED_SCHEMA, REJECTED_TOPIC, SCHEMAS, TOPICS, message_json_schema

__all__ = ["McapLog", "FoxgloveScene", "COMPRESSION"]

COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
"""Chunk compressions by name (the ``mcap`` library compresses with ``zstandard`` and ``lz4``)."""

log = logging.getLogger(__name__)


class FoxgloveScene(Protocol):
    """What the writer asks of the Foxglove conversion (:class:`shared.recording.foxglove.SceneBuilder`).

    Each method returns a JSON-ready ``foxglove.SceneUpdate`` or ``foxglove.FrameTransforms`` object
    stamped ``stamp`` (seconds), or None when it has nothing to draw (e.g. no robot model).
    """

    def static_scene(self, stamp: float) -> dict[str, Any]:
        """Table and cups (``/viz/scene``)."""
        ...

    def base_transform(self, stamp: float) -> dict[str, Any]:
        """The transform world -> robot base (``/tf``)."""
        ...

    def plan_paths(self, plan: Plan, stamp: float | None = None) -> dict[str, Any] | None:
        """The candidate end-effector paths (``/viz/plan``)."""
        ...

    def robot_spheres(self, state: RobotState, stamp: float | None = None) -> dict[str, Any] | None:
        """The robot's collision spheres (``/viz/robot``)."""
        ...

    def end_effector_transform(self, state: RobotState, stamp: float | None = None) -> dict[str, Any] | None:
        """The transform world -> end effector (``/tf``)."""
        ...

    def occupancy_cubes(self, occ: OccupancyGrid, stamp: float | None = None) -> dict[str, Any]:
        """The occupied voxels (``/viz/occupancy``)."""
        ...

    def human_body(self, pose: HumanPose, stamp: float | None = None) -> dict[str, Any] | None:
        """The human's body (``/viz/human``)."""
        ...


class McapLog:
    """Thread-safe MCAP writer of Foresight messages (call :meth:`on_sample` from any thread).

    Args:
        path: Output file (parent directories are created).
        keys: The key expressions of the run (its prefix).
        builder: Builds the Foxglove scene channels (e.g. a SceneBuilder; None: no Foxglove channels).
        viz_period_s: Smallest time (message stamps) between two Foxglove updates of the robot, the
            human or the occupancy (plans are drawn every time).
        chunk_size: Chunk size in bytes.
        flush_period_s: Longest time an incomplete chunk stays in memory.
        scene_text: The scene file's text, attached as ``scene.toml``.
        run_metadata: String map written as metadata ``foresight.run``.
        clock: Log-time source in nanoseconds (default ``time.time_ns``).
        viz_thread: Build the Foxglove updates of received messages on a background thread
            (:class:`~shared.recording.background.BackgroundWorker`), so that a caller logging from its
            receive path never waits for them (an occupancy's cubes take 13-22 ms); updates are stamped
            with the message's receive time all the same, and one that finds ``viz_pending`` waiting is
            dropped (counted, metadata ``foresight.viz``). False: built in :meth:`log_message`.
        viz_pending: Foxglove updates that may wait for the background thread.
        compression: Chunk compression, ``"zstd"``, ``"lz4"`` or ``"none"``. A chunk is compressed as a
            whole when it is closed, so a killed writer's file still reads back up to its last chunk.
    """

    def __init__(self, path: str | os.PathLike[str], keys: Keys, builder: FoxgloveScene | None = None,
                 viz_period_s: float = 0.2, chunk_size: int = 256 * 1024, flush_period_s: float = 1.0,
                 scene_text: str | None = None, run_metadata: dict[str, str] | None = None,
                 clock: Callable[[], int] = time.time_ns, viz_thread: bool = True, viz_pending: int = 16,
                 compression: str = "zstd") -> None:
        if compression not in COMPRESSION:
            raise ValueError(f"MCAP compression must be one of {', '.join(COMPRESSION)}, got {compression!r}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.keys = keys
        self.builder = builder
        self.viz_period_s = viz_period_s
        self.flush_period_s = flush_period_s
        self._clock = clock
        self._lock = threading.RLock()
        self._file = DirectFile(self.path)
        self._writer = Writer(typing.cast(io.BufferedWriter, self._file), chunk_size=chunk_size,
                              compression=COMPRESSION[compression])
        self._writer.start(profile=PROFILE, library="foresight executor")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._last_flush = time.monotonic()
        self._last_viz: dict[str, float] = {}
        self._closed = False
        self.counts: dict[str, int] = {}
        self.rejects: dict[str, int] = {}
        self.reject_reasons: dict[str, int] = {}
        self.viz_errors = 0
        self._expected = keys.data_keys()
        if scene_text is not None:
            now = self._clock()
            self._writer.add_attachment(now, now, "scene.toml", "application/toml", scene_text.encode())
        if run_metadata:
            self._writer.add_metadata("foresight.run", {k: str(v) for k, v in run_metadata.items()})
        if builder is not None:  # stamped and logged at the same (receive-time) clock as every later update
            now = self._clock()
            self.write_json("/viz/scene", builder.static_scene(now / 1e9), now)
            self.write_json("/tf", builder.base_transform(now / 1e9), now)
        self._writer.flush()
        self._viz = (BackgroundWorker(self._visualise_item, "mcap-foxglove", viz_pending)
                     if builder is not None and viz_thread else None)

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
        self._writer.add_message(channel_id=channel, log_time=log_time, data=data, publish_time=publish_time,
                                 sequence=self.counts.get(topic, 0))
        self.counts[topic] = self.counts.get(topic, 0) + 1
        self.flush_if_due()

    def write_json(self, topic: str, obj: dict[str, Any], log_time: int | None = None) -> None:
        """Write a JSON message on a Foxglove (or other JSON) topic."""
        data = dumps_sliced(obj).encode()  # outside the lock (an occupancy's cubes: ~0.6 MB)
        with self._lock:
            if self._closed:
                return
            if topic == REJECTED_TOPIC:
                name, schema = "foresight.Rejected", REJECTED_SCHEMA
            else:
                name = TOPICS[topic]
                schema = SCHEMAS[name]
            cid = self._channel_id(topic, name, schema, "json")
            t = self._clock() if log_time is None else log_time
            self._add(cid, topic, data, t, t)

    def write_ros2(self, topic: str, msgtype: str, data: bytes, log_time: int | None = None) -> None:
        """Write a ROS 2 message as sent or received (CDR, schema ``ros2msg``: its definition from ``rosbags``)."""
        with self._lock:
            if self._closed:
                return
            if topic not in self._channels:
                from rosbags.typesys import Stores, get_typestore

                msgdef, _ = get_typestore(Stores.ROS2_JAZZY).generate_msgdef(msgtype, ros_version=2)
                sid = self._writer.register_schema(name=msgtype, encoding="ros2msg", data=msgdef.encode())
                self._channels[topic] = self._writer.register_channel(topic, "cdr", sid)
            t = self._clock() if log_time is None else log_time
            self._add(self._channels[topic], topic, data, t, t)

    # -- samples -------------------------------------------------------------------------------

    def on_sample(self, key: str, payload: bytes) -> Message | None:
        """Decode and log one sample received on ``key``; returns the message (None if rejected)."""
        log_time = self._clock()
        try:
            msg: Message = decode(payload, self._expected.get(key))
        except ProtocolError as exc:
            self.reject(key, payload, str(exc), log_time, reason=exc.reason)
            return None
        self.log_message(key, payload, msg, log_time)
        return msg

    def log_message(self, key: str, payload: bytes, msg: Message, log_time: int | None = None) -> None:
        """Log a payload already decoded (and so validated) as ``msg`` on ``key``'s channel."""
        log_time = self._clock() if log_time is None else log_time
        stamp = float(getattr(msg, "stamp", -1.0))
        publish = int(stamp * 1e9) if stamp >= 0 else log_time
        with self._lock:
            if self._closed:
                return
            cid = self._channels.get(key)
            if cid is None:  # the schema is built once per channel, not per message
                cid = self._channel_id(key, f"foresight.{msg.TYPE}", message_json_schema(MESSAGE_TYPES[msg.TYPE]),
                                       "msgpack")
            self._add(cid, key, bytes(payload), log_time, publish)
        topic = self._viz_topic(msg) if self.builder is not None else None
        if topic is None:
            return
        stamp = float(getattr(msg, "stamp", 0.0))
        with self._lock:
            if not self._due(topic, stamp):
                return
            # a dropped update does not count as drawn: the next message of its kind may draw instead
            if self._viz is None or self._viz.submit((msg, log_time)):
                self._last_viz[topic] = stamp
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
        self.write_json(REJECTED_TOPIC, {"key": key, "reason": reason, "error": error[:500], "size": len(payload),
                                         "head_hex": bytes(payload[:64]).hex()}, log_time)

    def _due(self, topic: str, stamp: float) -> bool:
        """Whether ``topic`` gets an update now: plans always, the others at most ``viz_period_s`` apart (stamps)."""
        last = self._last_viz.get(topic)
        return topic == "/viz/plan" or last is None or not 0.0 <= stamp - last < self.viz_period_s - 1e-9

    @staticmethod
    def _viz_topic(msg: Message) -> str | None:
        """The Foxglove channel that draws ``msg`` (None: none does)."""
        for kind, topic in ((Plan, "/viz/plan"), (RobotState, "/viz/robot"), (OccupancyGrid, "/viz/occupancy"),
                            (HumanPose, "/viz/human")):
            if isinstance(msg, kind):
                return topic
        return None

    def _visualise_item(self, item: tuple[Message, int]) -> None:
        self._visualise(*item)

    def _visualise(self, msg: Message, log_time: int) -> None:
        # One time base for everything Foxglove sees: the entities and transforms are stamped with the
        # receive time (the record's log time), never with the message's own stamp, which is simulated
        # time (seconds from 0, i.e. 1970) in lock-step runs and wall time in real time.
        b = self.builder
        assert b is not None
        t = log_time / 1e9
        try:
            if isinstance(msg, Plan):
                upd = b.plan_paths(msg, stamp=t)
                if upd is not None:
                    self.write_json("/viz/plan", upd, log_time)
            elif isinstance(msg, RobotState):
                upd = b.robot_spheres(msg, stamp=t)
                if upd is not None:
                    self.write_json("/viz/robot", upd, log_time)
                tf = b.end_effector_transform(msg, stamp=t)
                if tf is not None:
                    self.write_json("/tf", tf, log_time)
            elif isinstance(msg, OccupancyGrid):
                self.write_json("/viz/occupancy", b.occupancy_cubes(msg, stamp=t), log_time)
            elif isinstance(msg, HumanPose):
                upd = b.human_body(msg, stamp=t)
                if upd is not None:
                    self.write_json("/viz/human", upd, log_time)
        except Exception:  # a visualisation bug must never cost the raw log
            self.viz_errors += 1
            if self.viz_errors == 1 or self.viz_errors % 100 == 0:
                log.exception("mcap log: Foxglove update for %s failed (%d so far)", msg.TYPE, self.viz_errors)

    # -- lifecycle -----------------------------------------------------------------------------

    def flush_if_due(self) -> None:
        """Write the open chunk if it is older than ``flush_period_s`` (call it periodically)."""
        if time.monotonic() - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Write the open chunk to the file now."""
        with self._lock:
            if not self._closed:
                self._writer.flush()
                self._last_flush = time.monotonic()

    def close(self) -> None:
        """Finish the queued Foxglove updates, write the reject counts, the summary and the footer; idempotent."""
        if self._viz is not None:
            self._viz.close()  # outside the lock: the updates still queued take it to write
        with self._lock:
            if self._closed:
                return
            if self._viz is not None:  # unfinished: still queued when the worker's close timed out
                self._writer.add_metadata("foresight.viz", {"dropped": str(self._viz.dropped),
                                                            "unfinished": str(self._viz.pending),
                                                            "errors": str(self.viz_errors)})
            self._writer.add_metadata("foresight.rejects", {k: str(v) for k, v in sorted(self.rejects.items())})
            self._writer.add_metadata("foresight.rejects.reasons",
                                      {k: str(v) for k, v in sorted(self.reject_reasons.items())})
            self._writer.finish()
            self._file.fsync()
            self._file.close()
            self._closed = True
        log.info("mcap log: wrote %s (%d messages on %d channels, %d rejected, %d Foxglove updates dropped)",
                 self.path, sum(self.counts.values()), len(self.counts), sum(self.rejects.values()), self.viz_dropped)

    @property
    def viz_dropped(self) -> int:
        """Foxglove updates dropped because ``viz_pending`` were already waiting for the background thread."""
        return self._viz.dropped if self._viz is not None else 0

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
