"""The channels' JSON Schemas: one per message type, generated from the protocol dataclasses, and the plots'."""

from __future__ import annotations

import dataclasses
import json

import jsonschema

from shared.foxglove.stream import SCHEMAS, TOPICS
from shared.protocol import MESSAGE_TYPES
from shared.recording.schemas import REJECTED_SCHEMA, message_json_schema


def test_schemas_describe_every_field_of_every_message_type() -> None:
    for cls in MESSAGE_TYPES.values():
        schema = message_json_schema(cls)
        jsonschema.Draft202012Validator.check_schema(schema)
        assert schema["title"] == f"foresight.{cls.TYPE}"
        assert set(schema["properties"]) == {"_type", "_v"} | {f.name for f in dataclasses.fields(cls)}
    plan = message_json_schema(MESSAGE_TYPES["Plan"])["properties"]["trajectories"]
    assert plan["x-dtype"] == "float32" and plan["x-shape"] == ["K", "T", "D"]
    for schema in SCHEMAS.values():
        if schema.encoding == "jsonschema":
            jsonschema.Draft202012Validator.check_schema(json.loads(schema.data))
    jsonschema.Draft202012Validator.check_schema(REJECTED_SCHEMA)
    assert TOPICS == {t: s.name for t, s in SCHEMAS.items()}
