"""The wire contract: key expressions and message schemas (documented in docs/protocol.md).

Every message is a msgpack map with ``_type`` (the message type name), ``_v`` (the lowest schema version that
holds it, at most :data:`SCHEMA_VERSION`) and one entry per field. Numeric arrays travel as maps
``{"dtype": "<f8", "shape": [..], "data": <raw little-endian bytes>}``.

:func:`decode` validates everything (type, version, field presence, scalar types, array dtypes,
shapes and finiteness, and per-message invariants) and raises :class:`ProtocolError`, whose message
names the offending field.

Modules: :mod:`~shared.protocol.schema` (the base class, array fields, the version, the rejection
reasons), :mod:`~shared.protocol.messages` (the message types), :mod:`~shared.protocol.keys` (key
expressions), :mod:`~shared.protocol.codec` (encode / decode), :mod:`~shared.protocol.limits` (every
size and value bound), :mod:`~shared.protocol.validation` (values checked on receipt against the
receiver's expectations), :mod:`~shared.protocol.receipt` (decode + values + per-sender order, what
the services call). Import the names from here (``from shared.protocol import Plan, decode``).
"""

from .codec import decode, encode
from .keys import HUMAN_SOURCES, ROUTES, SENSOR, SERVICES, Keys
from .messages import (
    AT_REST,
    DEMO_EVENTS,
    MESSAGE_TYPES,
    ClassPosterior,
    ClockTick,
    DemoMarker,
    HumanKeypoints,
    HumanPose,
    OccupancyGrid,
    Plan,
    RobotState,
)
from .receipt import Receipt, SenderOrder
from .schema import READABLE_VERSIONS, REASONS, SCHEMA_VERSION, ArraySpec, Message, ProtocolError
from .validation import Expectations, GridSpec, RobotSpec, check_values

__all__ = [
    "SCHEMA_VERSION",
    "READABLE_VERSIONS",
    "ProtocolError",
    "REASONS",
    "ArraySpec",
    "Message",
    "HumanKeypoints",
    "HumanPose",
    "DemoMarker",
    "ClassPosterior",
    "OccupancyGrid",
    "Plan",
    "RobotState",
    "ClockTick",
    "MESSAGE_TYPES",
    "AT_REST",
    "DEMO_EVENTS",
    "Keys",
    "SERVICES",
    "HUMAN_SOURCES",
    "SENSOR",
    "ROUTES",
    "encode",
    "decode",
    "Expectations",
    "RobotSpec",
    "GridSpec",
    "check_values",
    "Receipt",
    "SenderOrder",
]
