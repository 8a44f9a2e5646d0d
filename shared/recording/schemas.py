"""The JSON Schemas of a recording's channels.

One per Foresight message type, the rejects channel's, and Foxglove's well-known
``foxglove.SceneUpdate`` / ``foxglove.FrameTransforms``.

Every channel of an MCAP log carries its schema (encoding ``jsonschema``):

* a message channel (message encoding ``msgpack``): :func:`message_json_schema`, generated from the
  :mod:`shared.protocol` dataclasses;
* ``/foresight/rejected`` (JSON): :data:`REJECTED_SCHEMA`;
* the Foxglove channels (JSON, :data:`TOPICS`): :data:`SCHEMAS`. Foxglove recognises a channel by its
  schema name and, for ``message_encoding = "json"``, by a JSON Schema that describes the fields. These
  are written from Foxglove's published message documentation (only the fields this project sends,
  plus the container fields) by :func:`scene_update_schema` / :func:`frame_transforms_schema`.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

from shared.protocol import SCHEMA_VERSION, Message

__all__ = ["PROFILE", "REJECTED_TOPIC", "REJECTED_SCHEMA", "message_json_schema", "TOPICS", "scene_update_schema",
           "frame_transforms_schema", "SCHEMAS"]

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
    """
    hints = typing.get_type_hints(cls)
    props: dict[str, Any] = {
        "_type": {"const": cls.TYPE, "description": "message type name"},
        "_v": {"const": SCHEMA_VERSION, "description": "schema version"},
    }
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
    doc = (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
    return {"title": f"foresight.{cls.TYPE}", "description": doc, "type": "object", "properties": props,
            "required": list(props)}


# ----------------------------------------------------------------------------------------------
# Foxglove

# Foxglove channels of a recording: topic -> schema name
TOPICS: dict[str, str] = {
    "/viz/scene": "foxglove.SceneUpdate",      # table and cups
    "/viz/robot": "foxglove.SceneUpdate",      # robot collision spheres
    "/viz/occupancy": "foxglove.SceneUpdate",  # occupied voxels
    "/viz/plan": "foxglove.SceneUpdate",       # candidate end-effector paths
    "/viz/human": "foxglove.SceneUpdate",      # human body segments
    "/tf": "foxglove.FrameTransforms",         # world -> robot base, end effector
}


def _num(desc: str) -> dict[str, Any]:
    return {"type": "number", "description": desc}


def _obj(title: str, desc: str, props: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "description": desc, "type": "object", "properties": props}


def _vec3(desc: str) -> dict[str, Any]:
    return _obj("foxglove.Vector3", desc, {a: _num(f"{a} coordinate length") for a in "xyz"})


def _point3(desc: str) -> dict[str, Any]:
    return _obj("foxglove.Point3", desc, {a: _num(f"{a} coordinate position") for a in "xyz"})


def _quat(desc: str) -> dict[str, Any]:
    return _obj("foxglove.Quaternion", desc, {a: _num(f"{a} value") for a in "xyzw"})


def _color(desc: str) -> dict[str, Any]:
    return _obj("foxglove.Color", desc, {c: _num(f"{n} value between 0 and 1") for c, n in
                                         (("r", "Red"), ("g", "Green"), ("b", "Blue"), ("a", "Alpha"))})


def _pose(desc: str) -> dict[str, Any]:
    return _obj("foxglove.Pose", desc, {"position": _vec3("Point denoting position in 3D space"),
                                        "orientation": _quat("Quaternion denoting orientation in 3D space")})


def _time(desc: str, signed: bool = False) -> dict[str, Any]:
    sec: dict[str, Any] = {"type": "integer"} if signed else {"type": "integer", "minimum": 0}
    return {"type": "object", "title": "duration" if signed else "time", "description": desc,
            "properties": {"sec": sec, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}


def _array(items: dict[str, Any], desc: str) -> dict[str, Any]:
    return {"type": "array", "items": items, "description": desc}


def _primitive(title: str, desc: str, **extra: Any) -> dict[str, Any]:
    props: dict[str, Any] = {"pose": _pose("Position of the center and orientation")}
    props.update(extra)
    props["color"] = _color("Color")
    return _obj(title, desc, props)


def scene_update_schema() -> dict[str, Any]:
    """JSON Schema of ``foxglove.SceneUpdate`` (fields used here: cubes, spheres, cylinders, lines)."""
    line = _obj("foxglove.LinePrimitive", "A primitive representing a series of points connected by lines", {
        "type": {"title": "foxglove.LineType", "description": "Drawing primitive to use for lines",
                 "oneOf": [{"title": "LINE_STRIP", "const": 0}, {"title": "LINE_LOOP", "const": 1},
                           {"title": "LINE_LIST", "const": 2}]},
        "pose": _pose("Origin of lines relative to reference frame"),
        "thickness": _num("Width of the line"),
        "scale_invariant": {"type": "boolean", "description": "Whether thickness is in pixels (true) or metres"},
        "points": _array(_point3("Point"), "Points along the line"),
        "color": _color("Solid color to use for the whole line"),
        "colors": _array(_color("Color"), "Per-point colors (optional)"),
        "indices": _array({"type": "integer", "minimum": 0}, "Indices into the points and colors arrays"),
    })
    entity = _obj("foxglove.SceneEntity", "A visual element in a 3D scene", {
        "timestamp": _time("Timestamp of the entity"),
        "frame_id": {"type": "string", "description": "Frame of reference"},
        "id": {"type": "string", "description": "Identifier; replaces any prior entity on the topic with this id"},
        "lifetime": _time("How long the entity stays (zero: until replaced or deleted)", signed=True),
        "frame_locked": {"type": "boolean", "description": "Follow frame_id as it moves"},
        "metadata": _array(_obj("foxglove.KeyValuePair", "A key with its value",
                                {"key": {"type": "string"}, "value": {"type": "string"}}), "Metadata"),
        "arrows": _array(_obj("foxglove.ArrowPrimitive", "An arrow", {}), "Arrow primitives"),
        "cubes": _array(_primitive("foxglove.CubePrimitive", "A cube or rectangular prism",
                                   size=_vec3("Size of the cube along each axis")), "Cube primitives"),
        "spheres": _array(_primitive("foxglove.SpherePrimitive", "A sphere or ellipsoid",
                                     size=_vec3("Size (diameter) of the sphere along each axis")),
                          "Sphere primitives"),
        "cylinders": _array(_primitive("foxglove.CylinderPrimitive", "A cylinder, cone or truncated cone",
                                       size=_vec3("Size of the bounding box"),
                                       bottom_scale=_num("0-1, ratio of the bottom diameter to size.x/y"),
                                       top_scale=_num("0-1, ratio of the top diameter to size.x/y")),
                            "Cylinder primitives"),
        "lines": _array(line, "Line primitives"),
        "triangles": _array(_obj("foxglove.TriangleListPrimitive", "A set of triangles", {}), "Triangles"),
        "texts": _array(_obj("foxglove.TextPrimitive", "A text label", {}), "Text primitives"),
        "models": _array(_obj("foxglove.ModelPrimitive", "A 3D model", {}), "Model primitives"),
    })
    deletion = _obj("foxglove.SceneEntityDeletion", "Command to remove previously published entities", {
        "timestamp": _time("Only matching entities earlier than this timestamp are deleted"),
        "type": {"title": "foxglove.SceneEntityDeletionType", "oneOf": [{"title": "MATCHING_ID", "const": 0},
                                                                         {"title": "ALL", "const": 1}]},
        "id": {"type": "string", "description": "Identifier which must match if type is MATCHING_ID"},
    })
    out = _obj("foxglove.SceneUpdate", "An update to the entities displayed in a 3D scene", {
        "deletions": _array(deletion, "Scene entities to delete"),
        "entities": _array(entity, "Scene entities to add or replace"),
    })
    return out


def frame_transforms_schema() -> dict[str, Any]:
    """JSON Schema of ``foxglove.FrameTransforms``."""
    tf = _obj("foxglove.FrameTransform", "A transform between two reference frames in 3D space", {
        "timestamp": _time("Timestamp of transform"),
        "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
        "child_frame_id": {"type": "string", "description": "Name of the child frame"},
        "translation": _vec3("Translation component of the transform"),
        "rotation": _quat("Rotation component of the transform"),
    })
    return _obj("foxglove.FrameTransforms", "An array of FrameTransform messages",
                {"transforms": _array(tf, "Array of transforms")})


SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.SceneUpdate": scene_update_schema(),
    "foxglove.FrameTransforms": frame_transforms_schema(),
}
