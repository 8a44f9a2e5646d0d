"""The scene channels of a recording, read back with ``protobuf`` and the schemas the file carries.

Nothing here imports ``foxglove-sdk``: a scene message is decoded from the ``FileDescriptorSet`` its
channel's schema holds (schema encoding ``protobuf``), or parsed as JSON (``jsonschema``), as any MCAP
consumer would. The tests use it to check what the SDK wrote; ``foresight log snapshot`` draws from it.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError, Message
from mcap.reader import make_reader
from mcap.records import Channel, Schema
from mcap.records import Message as McapMessage

from shared.recording.reader import DAMAGED, log_path, open_records, summary_damage

__all__ = ["SceneRecord", "SceneDecodeError", "SchemaDecoder", "read_scene", "scene_stamps"]


class SceneDecodeError(ValueError):
    """A scene message or its schema does not decode; the message names the channel."""


@dataclass
class SceneRecord:
    """One decoded scene message: a protobuf message, or a dict for a JSON channel."""

    topic: str
    schema_name: str
    log_time: int
    publish_time: int
    message: Message | dict[str, Any]


class SchemaDecoder:
    """Decodes messages of the schemas it is given, building each schema's message class once."""

    def __init__(self) -> None:
        self._classes: dict[tuple[str, bytes], type[Message]] = {}

    def message_class(self, name: str, data: bytes) -> type[Message]:
        """The protobuf class of message ``name`` in the serialised ``FileDescriptorSet`` ``data``."""
        key = (name, bytes(data))
        if key not in self._classes:
            fds = descriptor_pb2.FileDescriptorSet.FromString(bytes(data))
            pool = descriptor_pool.DescriptorPool()
            pending = list(fds.file)
            while pending:  # a file is added after the files it imports, whatever their order in the set
                added = [f for f in pending if all(d in {g.name for g in fds.file if g not in pending}
                                                   for d in f.dependency)]
                if not added:
                    raise SceneDecodeError(f"schema {name}: unresolved imports in {[f.name for f in pending]}")
                for f in added:
                    pool.Add(f)
                    pending.remove(f)
            self._classes[key] = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
        return self._classes[key]

    def decode(self, topic: str, schema_name: str, schema_encoding: str, schema_data: bytes,
               data: bytes) -> Message | dict[str, Any]:
        """One message of ``topic`` under its channel's schema."""
        try:
            if schema_encoding == "protobuf":
                return self.message_class(schema_name, schema_data).FromString(bytes(data))
            if schema_encoding == "jsonschema":
                return json.loads(data)
        except (DecodeError, KeyError, TypeError, ValueError) as exc:
            raise SceneDecodeError(f"{topic} ({schema_name}): {exc}") from exc
        raise SceneDecodeError(f"{topic}: schema encoding {schema_encoding!r} is not protobuf or jsonschema")


def read_scene(path: str | Path, topics: set[str] | None = None) -> Iterator[SceneRecord]:
    """The scene messages of a log (channels ``/viz/...`` and ``/tf``, or ``topics``) in log-time order.

    The scene is written off the receive path, so the file is not in log-time order. A complete log (its
    summary holds the chunk index) is read through the index in log-time order, a chunk at a time, so the
    first record comes at once and memory stays that of a few chunks (before, every scene message of the file
    was held and sorted first: 300 MB for a 17-minute run). A log whose writer was killed has no summary, and one
    whose summary's CRC does not hold has none to trust (a flipped bit in a chunk index drew an earlier moment as
    the last): it is read record by record, as :func:`shared.recording.reader.read_log` does, and what its
    complete chunks hold is held and sorted.

    Raises:
        SceneDecodeError: A message does not decode under its channel's schema.
        OSError: The file cannot be read.
        shared.runtime.UserError: The file is missing or not an MCAP file (:func:`open_records`).
    """
    def wanted(topic: str) -> bool:
        return topic in topics if topics is not None else (topic.startswith("/viz/") or topic == "/tf")

    with open_records(path):  # what the path is (missing, a directory, a pipe, not an MCAP file) is said here
        pass
    decoder = SchemaDecoder()
    with log_path(path).open("rb") as f:
        indexed = make_reader(f, validate_crcs=True)
        try:  # an index whose CRC does not hold is not followed: read in file order below (summary_damage)
            summary = None if summary_damage(path) else indexed.get_summary()
        except DAMAGED:
            summary = None
        if summary is not None and summary.chunk_indexes:
            chosen = [c.topic for c in summary.channels.values() if wanted(c.topic)]
            if not chosen:  # no scene channel: nothing to read
                return
            yielded = 0
            try:
                for schema, channel, message in indexed.iter_messages(topics=chosen, log_time_order=True):
                    if schema is None:
                        continue
                    yield SceneRecord(channel.topic, schema.name, message.log_time, message.publish_time,
                                      decoder.decode(channel.topic, schema.name, schema.encoding, schema.data,
                                                     message.data))
                    yielded += 1
            except SceneDecodeError:  # a ValueError too, but a payload's fault, not the file's: said, not swallowed
                raise
            except DAMAGED:  # a damaged chunk (a flipped bit): the scene up to it stands, as the other tools read
                if yielded:  # a log up to its damage (foresight log says the file is not whole)
                    return
            else:
                return
    schemas: dict[int, Schema] = {}
    channels: dict[int, tuple[Channel, Schema]] = {}
    raw: list[tuple[int, int, int, bytes]] = []  # (log_time, publish_time, channel id, data)
    with open_records(path) as reader:
        try:
            for rec in reader.records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel) and rec.schema_id in schemas:
                    if wanted(rec.topic):
                        channels[rec.id] = (rec, schemas[rec.schema_id])
                elif isinstance(rec, McapMessage) and rec.channel_id in channels:
                    raw.append((rec.log_time, rec.publish_time, rec.channel_id, bytes(rec.data)))
        except DAMAGED:
            if not schemas:  # not an MCAP file at all
                raise
            # else a truncated end: what was read stands (foresight log info says whether a file is complete)
    raw.sort(key=lambda r: r[0])  # the scene is written off the receive path: in file order, not time order
    for log_time, publish_time, cid, data in raw:
        channel, schema = channels[cid]
        yield SceneRecord(channel.topic, schema.name, log_time, publish_time,
                          decoder.decode(channel.topic, schema.name, schema.encoding, schema.data, data))


def _ns(t: Any) -> int:
    if isinstance(t, dict):  # a JSON chart's {"sec", "nsec"}
        return int(t["sec"]) * 1_000_000_000 + int(t["nsec"])
    return int(t.seconds) * 1_000_000_000 + int(t.nanos)  # google.protobuf.Timestamp


def scene_stamps(path: str | Path) -> list[tuple[str, str, int, int, int]]:
    """Every stamped item of a log's scene channels as ``(topic, item, stamp ns, log_time, publish_time)``.

    An item is a scene entity (its id), a transform (its child frame), a point cloud (``"points"``) or a
    chart (``"chart"``).
    """
    out = []
    for r in read_scene(path):
        m = r.message
        if isinstance(m, dict):
            items = [("chart", m["timestamp"])]
        elif r.schema_name == "foxglove.SceneUpdate":
            items = [(e.id, e.timestamp) for e in m.entities]  # type: ignore[attr-defined]
        elif r.schema_name == "foxglove.FrameTransforms":
            items = [(t.child_frame_id, t.timestamp) for t in m.transforms]  # type: ignore[attr-defined]
        else:
            items = [("points", m.timestamp)]  # type: ignore[attr-defined]
        out += [(r.topic, ident, _ns(t), r.log_time, r.publish_time) for ident, t in items]
    return out
