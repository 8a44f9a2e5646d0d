"""How rmw_zenoh puts a ROS 2 topic on Zenoh: data keys, the sample attachment, graph liveliness tokens.

Followed: ros2/rmw_zenoh ``docs/design.md`` and ``rmw_zenoh_cpp/src/detail/`` (``attachment_helpers.cpp``:
``AttachmentData::serialize_to_zbytes`` with zenoh-cpp's ``ext::Serializer``, the layout of rmw_zenoh_cpp 0.2.4 (Jazzy),
0.6.0 (Rolling) and 0.1.2 (Humble) on, April-June 2025, PR #601; ``liveliness_utils.cpp``: the tokens and the GID;
``qos.cpp``: the QoS defaults). Pure: no Zenoh, no ROS; the ``rosbags`` type store gives the message definitions, CDR
and the RIHS01 hashes.

* data key: ``<domain>/<topic without its leading slash>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>``;
* payload: CDR, little-endian, with its 4-byte encapsulation header ``00 01 00 00``;
* attachment, 33 bytes: int64 LE sequence number, int64 LE source timestamp (ns since the epoch),
  the byte 16 (the GID's length), the 16-byte GID. A ROS 2 subscriber drops a sample without one;
* graph: ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/<namespace>/<node>``
  ``[/<topic, / as %>/<dds type>/<hash>/<qos>]``, empty names as ``%``;
* GID: XXH3-128 of the entity's token, its low 64 bits then its high 64, each little-endian.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

import xxhash

__all__ = ["Attachment", "ATTACHMENT_SIZE", "GID_SIZE", "dds_type", "data_key", "mangle", "node_token",
           "endpoint_token", "Endpoint", "parse_endpoint_token", "qos_chunk", "AttachmentError", "ROS_NAME",
           "topic_problem", "MAX_TOPIC_LENGTH", "endpoint_gid", "HUMBLE_TYPE_HASH"]

GID_SIZE = 16
ATTACHMENT_SIZE = 8 + 8 + 1 + GID_SIZE
_LAYOUT = struct.Struct("<qqB16s")
_LABELLED = b"\x0fsequence_number"  # how the older attachment starts: the label, after its LEB128 length
_RELEASES = "rmw_zenoh_cpp 0.2.4 (Jazzy), 0.6.0 (Rolling), 0.1.2 (Humble)"
HUMBLE_TYPE_HASH = "TypeHashNotSupported"
"""What rmw_zenoh on Humble puts where the type hash goes (Humble's messages have none)."""


class AttachmentError(ValueError):
    """A sample's attachment is missing or is not rmw_zenoh's."""


@dataclass(frozen=True)
class Attachment:
    """rmw_zenoh's per-sample metadata."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        """The 33 bytes."""
        if len(self.gid) != GID_SIZE:
            raise AttachmentError(f"attachment: the GID must be {GID_SIZE} bytes, got {len(self.gid)}")
        return _LAYOUT.pack(self.sequence_number, self.source_timestamp_ns, GID_SIZE, self.gid)

    @classmethod
    def decode(cls, data: bytes | None) -> Attachment:
        """Parse 33 bytes.

        Raises:
            AttachmentError: Missing, of another size, or a GID length other than 16.
        """
        if data is None:
            raise AttachmentError("attachment: missing (rmw_zenoh sends one with every sample)")
        if data.startswith(_LABELLED):
            raise AttachmentError(f"attachment: {len(data)} bytes, labelled (sequence_number, source_timestamp, "
                                  f"source_gid): the attachment of rmw_zenoh_cpp before {_RELEASES}; Foresight "
                                  "speaks those releases and later (docs/ros2.md)")
        if len(data) != ATTACHMENT_SIZE:
            raise AttachmentError(f"attachment: {len(data)} bytes, rmw_zenoh's is {ATTACHMENT_SIZE} "
                                  f"(since {_RELEASES})")
        seq, stamp, n, gid = _LAYOUT.unpack(data)
        if n != GID_SIZE:
            raise AttachmentError(f"attachment: GID length {n}, expected {GID_SIZE}")
        return cls(seq, stamp, gid)


def dds_type(msgtype: str) -> str:
    """``sensor_msgs/msg/JointState`` -> ``sensor_msgs::msg::dds_::JointState_``."""
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


class TopicNameError(ValueError):
    """A ROS 2 topic name this bridge cannot use (not absolute, a wildcard, an empty part)."""


ROS_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
"""One token of a ROS 2 name (a node, a namespace part, a topic part): letters, digits and ``_``, not starting with a
digit (https://design.ros2.org/articles/topic_and_service_names.html; rmw's ``rmw_validate_full_topic_name``)."""

MAX_TOPIC_LENGTH = 255 - 8
"""rmw's ``RMW_TOPIC_MAX_NAME_LENGTH``: the longest topic name ROS 2 takes."""


def topic_problem(topic: str) -> str | None:
    """Why ``topic`` is no absolute ROS 2 topic name this bridge can map to a Zenoh key, or None when it is.

    ROS 2's rule for a fully qualified name (``rmw_validate_full_topic_name``): absolute, no empty part, each part a
    :data:`ROS_NAME` token, at most :data:`MAX_TOPIC_LENGTH` characters. What the configs check
    (``executor.ros2_joint_states``, ``tracker.ros2_topic``, ``simrobot.joint_states``), so that a bad name is one
    line at start-up, not a run waiting for a topic no ROS 2 node can have.
    """
    if not topic.startswith("/") or topic == "/" or topic.endswith("/") or "//" in topic:
        return f"an absolute topic (/a/b) without empty parts, got {topic!r}"
    bad = [part for part in topic[1:].split("/") if not ROS_NAME.fullmatch(part)]
    if bad:
        return (f"each part of a topic letters, digits and '_', not starting with a digit (ROS 2's rule): "
                f"{bad[0]!r} of {topic!r} is not")
    if len(topic) > MAX_TOPIC_LENGTH:
        return f"a topic of at most {MAX_TOPIC_LENGTH} characters (ROS 2's limit), got {len(topic)}"
    return None


def _topic(topic: str) -> str:
    problem = topic_problem(topic)
    if problem:
        raise TopicNameError(f"ROS 2 topic: {problem}")
    return topic[1:]


def data_key(domain: int, topic: str, msgtype: str, type_hash: str) -> str:
    """The Zenoh key of a topic's data."""
    return f"{domain}/{_topic(topic)}/{dds_type(msgtype)}/{type_hash}"


def mangle(name: str) -> str:
    """A name in a liveliness token: ``/`` -> ``%``, empty -> ``%``."""
    return name.replace("/", "%") if name and name != "/" else "%"


_INFINITE = "9223372036,854775807"  # rmw's RMW_DURATION_INFINITE, seconds,nanoseconds
_DEFAULT_DEPTH = 42  # rmw_zenoh's depth for a profile of depth 0 (qos.cpp)


def qos_chunk(reliable: bool = True, depth: int = 10, transient_local: bool = False, explicit: bool = True) -> str:
    """rmw_zenoh's QoS field of a token (``liveliness_utils.cpp``, ``qos_to_keyexpr``).

    ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>``,
    rmw's enum values (reliable 1, best effort 2; transient local 1, volatile 2; keep last 1; automatic 1). History
    keep last, the durations infinite, the liveliness automatic: what rmw_zenoh makes of a ROS 2 default profile.

    Args:
        reliable: Reliable, else best effort.
        depth: The history's depth (keep last).
        transient_local: Transient local, else volatile.
        explicit: Every component written, as this bridge declares its tokens: a blank one is read as the reader's
            default, and rmw_zenoh's defaults changed (durability: transient local until #521, volatile since).
            ``False``: blank where a component equals today's default, as rmw_zenoh writes it and re-writes a token
            it receives before hashing it into the GID (:func:`endpoint_gid`).
    """
    def field(value: str, default: str) -> str:
        return value if explicit or value != default else ""

    span = _INFINITE if explicit else ","  # deadline, lifespan, lease: always infinite here
    return (f"{field('1' if reliable else '2', '1')}:{field('1' if transient_local else '2', '2')}:"
            f"{field('1', '1')},{field(str(depth), str(_DEFAULT_DEPTH))}:{span}:{span}:{field('1', '1')},{span}")


def endpoint_gid(token: str) -> bytes:
    """The 16-byte GID rmw_zenoh gives the entity of liveliness ``token``: what ``ros2 topic info -v`` shows.

    ``liveliness_utils.cpp``, ``Entity::Entity``: XXH3-128 of the token string, ``low64`` then ``high64`` copied as
    the host (little-endian) stores them, i.e. the 128-bit value little-endian.
    """
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_SIZE, "little")


def node_token(domain: int, zid: str, node_id: int, namespace: str, node: str, enclave: str = "") -> str:
    """The liveliness token that makes a node visible (``ros2 node list``)."""
    return f"@ros2_lv/{domain}/{zid}/{node_id}/{node_id}/NN/{mangle(enclave)}/{mangle(namespace)}/{node}"


def endpoint_token(domain: int, zid: str, node_id: int, entity_id: int, kind: str, namespace: str, node: str,
                   topic: str, msgtype: str, type_hash: str, qos: str, enclave: str = "") -> str:
    """The liveliness token of a publisher (``kind`` ``MP``) or subscription (``MS``)."""
    if kind not in ("MP", "MS"):
        raise ValueError(f"entity kind must be MP or MS, got {kind!r}")
    _topic(topic)
    return (f"@ros2_lv/{domain}/{zid}/{node_id}/{entity_id}/{kind}/{mangle(enclave)}/{mangle(namespace)}/{node}/"
            f"{mangle(topic)}/{dds_type(msgtype)}/{type_hash}/{qos}")


@dataclass(frozen=True)
class Endpoint:
    """A publisher or subscription seen in the graph.

    Its session ``zid``, ``kind`` (``MP``/``MS``), node, topic and its type's DDS name (``type_name``:
    ``sensor_msgs::msg::dds_::JointState_``).
    """

    zid: str
    kind: str
    namespace: str
    node: str
    topic: str
    type_name: str = ""


def parse_endpoint_token(key: str) -> Endpoint | None:
    """The publisher or subscription a graph token declares (:func:`endpoint_token`); None for any other key."""
    parts = key.split("/")
    if len(parts) != 13 or parts[0] != "@ros2_lv" or parts[5] not in ("MP", "MS"):
        return None
    namespace = "/" if parts[7] == "%" else parts[7].replace("%", "/")
    return Endpoint(parts[2], parts[5], namespace, parts[8], parts[9].replace("%", "/"), parts[10])
