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


def test_a_version_1_payload_fits_its_channels_schema_and_a_version_2_one_too() -> None:
    """A log keeps the bytes it got: a version-1 ClassPosterior from an older predictor broke its channel's schema
    (``_v`` const 2, ``familiar`` required), which a schema-driven reader (Foxglove) would refuse."""
    import msgpack
    import numpy as np

    from shared.protocol import ClassPosterior, encode

    def as_json(payload: bytes) -> dict:  # msgpack bin is the schema's binary string: text for the validator
        raw = msgpack.unpackb(payload, raw=False)
        return {k: ({**v, "data": v["data"].hex()} if isinstance(v, dict) else v) for k, v in raw.items()}

    schema = message_json_schema(ClassPosterior)
    post = ClassPosterior(stamp=1.0, tick=-1, demo_id=0, index=3, class_names=["a", "b"],
                          posterior=np.array([0.25, 0.75]), log_likelihood=np.array([-1.0, -2.0]), familiarity=-2.5)
    v2 = as_json(encode(post))
    jsonschema.validate(v2, schema)
    v1 = {k: v for k, v in v2.items() if k not in ("familiar", "familiarity")} | {"_v": 1}
    jsonschema.validate(v1, schema)
    for bad in ({**v1, "familiar": True}, {k: v for k, v in v2.items() if k != "familiar"}, {**v2, "_v": 3}):
        try:
            jsonschema.validate(bad, schema)
        except jsonschema.ValidationError:
            continue
        raise AssertionError(f"{bad} fits the schema")
