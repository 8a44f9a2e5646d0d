"""The JSON Schemas of a recording's own channels: one per Foresight message type, and the rejects channel's.

Every channel of an MCAP log carries its schema:

* a message channel (message encoding ``msgpack``): :func:`message_json_schema` (encoding ``jsonschema``),
  generated from the :mod:`shared.protocol` dataclasses;
* ``/foresight/rejected`` (JSON): :data:`REJECTED_SCHEMA`;
* the scene channels: the schemas ``foxglove-sdk`` carries (protobuf) and the plots' JSON Schemas, in
  :data:`shared.foxglove.stream.SCHEMAS`.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

from shared.protocol import READABLE_VERSIONS, SCHEMA_VERSION, Message

__all__ = ["PROFILE", "REJECTED_TOPIC", "REJECTED_SCHEMA", "message_json_schema"]

PROFILE = "foresight"
REJECTED_TOPIC = "/foresight/rejected"
REJECTED_SCHEMA: dict[str, Any] = {
    "title": "foresight.Rejected",
    "description": "A payload on a Foresight key that was refused (decoding, values or order); it was not "
                   "logged on the key's channel",
    "type": "object",
    "properties": {
        "key": {"type": "string", "description": "Zenoh key expression the payload arrived on"},
        "reason": {"type": "string", "description": "Why, one of shared.protocol.REASONS (e.g. joint-limits)"},
        "error": {"type": "string", "description": "The decoder's or the validation's error, naming the field"},
        "size": {"type": "integer", "description": "Payload size in bytes"},
        "head_hex": {"type": "string", "description": "The first (at most 64) payload bytes, hex"},
    },
}


def message_json_schema(cls: type[Message]) -> dict[str, Any]:
    """JSON Schema of a message type's msgpack map (one property per dataclass field).

    Arrays are described as maps ``{dtype, shape, data}`` with ``data`` the raw little-endian bytes
    (msgpack ``bin``); ``x-dtype`` / ``x-shape`` give the expected dtype and shape (symbols such as
    ``"K"`` must agree across the fields of one message).

    A log keeps the bytes it received, and a receiver reads :data:`~shared.protocol.READABLE_VERSIONS`: ``_v`` may
    be any of them, and a field added after version 1 (:func:`shared.protocol.schema.added`) is required only of
    the versions that have it (a version-1 ``ClassPosterior`` from an older predictor, logged by this build, fits
    its channel's schema).
    """
    hints = typing.get_type_hints(cls)
    props: dict[str, Any] = {
        "_type": {"const": cls.TYPE, "description": "message type name"},
        "_v": {"enum": list(READABLE_VERSIONS), "description": "schema version: the lowest that holds the message "
               f"(this build's: {SCHEMA_VERSION})"},
    }
    later: dict[int, list[str]] = {}  # version -> the fields it added
    scalar = {float: {"type": "number"}, int: {"type": "integer"}, bool: {"type": "boolean"},
              str: {"type": "string"}}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        spec = f.metadata.get("array")
        if spec is not None:
            props[f.name] = {
                "type": "object",
                "description": f"numpy array, dtype {spec.dtype}, shape {list(spec.shape)}",
                "x-dtype": spec.dtype,
                "x-shape": list(spec.shape),
                "properties": {"dtype": {"type": "string"},
                               "shape": {"type": "array", "items": {"type": "integer", "minimum": 0}},
                               "data": {"type": "string", "contentEncoding": "binary",
                                        "description": "raw little-endian bytes (msgpack bin)"}},
                "required": ["dtype", "shape", "data"],
            }
        else:
            tp = hints[f.name]
            props[f.name] = ({"type": "array", "items": {"type": "string"}} if typing.get_origin(tp) is list
                             else dict(scalar[tp]))
        since = f.metadata.get("since", 1)
        if since > 1:
            later.setdefault(since, []).append(f.name)
            props[f.name]["description"] = f"added in schema version {since}"
    doc = (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
    added = {name for names in later.values() for name in names}
    out = {"title": f"foresight.{cls.TYPE}", "description": doc, "type": "object", "properties": props,
           "required": [p for p in props if p not in added]}
    if later:  # each version requires what it has, and an earlier one must not carry what came after it
        out["allOf"] = [{"if": {"properties": {"_v": {"minimum": v}}},
                         "then": {"required": names},
                         "else": {"not": {"anyOf": [{"required": [n]} for n in names]}}}
                        for v, names in sorted(later.items())]
    return out
