"""rmw_zenoh's formats, checked against the examples of ros2/rmw_zenoh docs/design.md."""

from __future__ import annotations

import struct

import pytest
import xxhash

from services.ros2.wire import (
    ATTACHMENT_SIZE,
    Attachment,
    AttachmentError,
    data_key,
    dds_type,
    endpoint_gid,
    endpoint_token,
    mangle,
    node_token,
    qos_chunk,
)

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"  # design.md's chatter


def test_keys_and_tokens_match_the_design_document() -> None:
    assert dds_type("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert data_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == \
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert node_token(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener") == \
        "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    assert endpoint_token(0, "8b20917502ee955ac4476e0266340d5c", 0, 10, "MP", "/", "talker", "/chatter",
                          "std_msgs/msg/String", STRING_HASH, qos_chunk(depth=7, explicit=False)) == (
        "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        f"{STRING_HASH}/::,7:,:,:,,")
    assert mangle("/robot1/chatter") == "%robot1%chatter" and mangle("") == "%"
    assert qos_chunk(reliable=False, depth=5, explicit=False) == "2::,5:,:,:,,"
    with pytest.raises(ValueError, match="absolute"):
        data_key(0, "chatter", "std_msgs/msg/String", STRING_HASH)
    with pytest.raises(ValueError, match="MP or MS"):
        endpoint_token(0, "z", 0, 1, "XX", "/", "n", "/t", "std_msgs/msg/String", STRING_HASH, qos_chunk())


def test_attachment_is_33_bytes_as_rmw_zenoh_lays_it_out() -> None:
    gid = bytes(range(16))
    raw = Attachment(7, 1_700_000_000_123_456_789, gid).encode()
    assert len(raw) == ATTACHMENT_SIZE == 33
    assert raw[:8] == struct.pack("<q", 7) and raw[8:16] == struct.pack("<q", 1_700_000_000_123_456_789)
    assert raw[16] == 16 and raw[17:] == gid
    assert Attachment.decode(raw) == Attachment(7, 1_700_000_000_123_456_789, gid)
    with pytest.raises(AttachmentError, match="missing"):
        Attachment.decode(None)
    with pytest.raises(AttachmentError, match="32 bytes"):
        Attachment.decode(raw[:-1])
    with pytest.raises(AttachmentError, match="GID length 15"):
        Attachment.decode(raw[:16] + b"\x0f" + raw[17:])
    with pytest.raises(AttachmentError, match="16 bytes"):
        Attachment(1, 2, b"short").encode()


INFINITE = "9223372036,854775807"  # rmw's RMW_DURATION_INFINITE


def test_qos_is_written_out_in_full_so_every_rmw_zenoh_reads_the_same_profile() -> None:
    """Blank fields took the reader's defaults: rmw_zenoh before #521 read a blank durability as transient local."""
    assert qos_chunk() == f"1:2:1,10:{INFINITE}:{INFINITE}:1,{INFINITE}"  # reliable, volatile, keep last 10
    assert qos_chunk(reliable=False, depth=5, transient_local=True) == f"2:1:1,5:{INFINITE}:{INFINITE}:1,{INFINITE}"
    # rmw_zenoh's keyexpr_to_qos: 6 ':' parts; history 2, deadline 2, lifespan 2, liveliness 3 ',' parts, none blank
    parts = qos_chunk().split(":")
    assert [len(p.split(",")) for p in parts] == [1, 1, 2, 2, 2, 3]
    assert all(f for p in parts for f in p.split(","))
    # as rmw_zenoh itself writes it (today's defaults blank: reliable, volatile, keep last, depth 42, infinite)
    assert qos_chunk(explicit=False) == "::,10:,:,:,,"
    assert qos_chunk(depth=42, transient_local=True, explicit=False) == ":1:,:,:,:,,"


def test_the_gid_is_xxh3_128_of_the_token_low_half_first_as_rmw_zenoh_stores_it() -> None:
    """liveliness_utils.cpp, Entity::Entity: memcpy of low64 then high64, each in the host's (little-endian) order."""
    # independent vector: XXH3-128 of no bytes is 99aa06d3014798d8 (high64) 6001c324468d497f (low64), xxHash's own
    assert endpoint_gid("") == bytes.fromhex("7f498d4624c30160" "d8984701d306aa99")
    token = endpoint_token(0, "8b20917502ee955ac4476e0266340d5c", 0, 10, "MP", "/", "talker", "/chatter",
                           "std_msgs/msg/String", STRING_HASH, qos_chunk(explicit=False))
    canonical = xxhash.xxh3_128_digest(token.encode())  # big-endian: high64, then low64
    assert endpoint_gid(token) == canonical[8:][::-1] + canonical[:8][::-1]
    assert len(endpoint_gid(token)) == 16 and endpoint_gid(token) != endpoint_gid(token + "x")


def _labelled_attachment(seq: int, stamp: int, gid: bytes) -> bytes:
    """rmw_zenoh_cpp's attachment before 0.2.4 (Jazzy) / 0.6.0 (Rolling): zenoh-ext serialized label, value pairs.

    A string is its LEB128 length and bytes, an int64 8 bytes LE, the GID a sequence (LEB128 count, bytes).
    """
    def label(name: str) -> bytes:
        return bytes([len(name)]) + name.encode()

    return (label("sequence_number") + struct.pack("<q", seq) + label("source_timestamp") + struct.pack("<q", stamp)
            + label("source_gid") + bytes([len(gid)]) + gid)


def test_an_older_rmw_zenoh_attachment_is_refused_naming_the_releases_that_speak_ours() -> None:
    raw = _labelled_attachment(1, 1_700_000_000_000_000_000, bytes(range(16)))
    assert len(raw) == 77
    with pytest.raises(AttachmentError) as err:
        Attachment.decode(raw)
    message = str(err.value)
    assert "77 bytes" in message and "before rmw_zenoh_cpp 0.2.4 (Jazzy), 0.6.0 (Rolling)" in message, message
    assert "\n" not in message
    with pytest.raises(AttachmentError, match=r"32 bytes, rmw_zenoh's is 33 \(since rmw_zenoh_cpp 0.2.4 \(Jazzy\)"):
        Attachment.decode(bytes(32))
