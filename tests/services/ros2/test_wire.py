"""rmw_zenoh's formats, checked against the examples of ros2/rmw_zenoh docs/design.md."""

from __future__ import annotations

import struct

import pytest

from services.ros2.wire import (
    ATTACHMENT_SIZE,
    Attachment,
    AttachmentError,
    data_key,
    dds_type,
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
                          "std_msgs/msg/String", STRING_HASH, qos_chunk(depth=7)) == (
        "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        f"{STRING_HASH}/::,7:,:,:,,")
    assert mangle("/robot1/chatter") == "%robot1%chatter" and mangle("") == "%"
    assert qos_chunk(reliable=False, depth=5) == "2::,5:,:,:,,"
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
