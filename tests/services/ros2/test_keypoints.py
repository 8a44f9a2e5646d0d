"""Keypoints as a ROS 2 PoseArray: round trip through CDR, lost points as NaN, the count checked."""

from __future__ import annotations

import numpy as np
import pytest

from services.ros2.core import KEYPOINTS_TYPE, Ros2Config, Ros2InputError, Ros2Mapping
from services.ros2.keypoints import keypoints_in, keypoints_out


def test_pose_array_round_trip_keeps_positions_lost_points_stamp_and_frame() -> None:
    mapping = Ros2Mapping(Ros2Config())
    pos = np.array([[0.1, 0.2, 1.0], [np.nan] * 3, [-0.3, 0.25, 1.4]])
    payload = keypoints_out(mapping, pos, 1700000000.25, "recorder")
    assert payload[:4] == b"\x00\x01\x00\x00"  # CDR little-endian
    stamp, frame_id, back = keypoints_in(mapping, payload, 3)
    assert stamp == pytest.approx(1700000000.25) and frame_id == "recorder"
    np.testing.assert_array_equal(back, pos)
    assert mapping.hashes[KEYPOINTS_TYPE].startswith("RIHS01_")


def test_pose_array_of_another_size_or_type_is_refused() -> None:
    mapping = Ros2Mapping(Ros2Config())
    payload = keypoints_out(mapping, np.zeros((2, 3)), 1.0, "recorder")
    with pytest.raises(Ros2InputError, match="2 poses, the tracker's point order has 3"):
        keypoints_in(mapping, payload, 3)
    with pytest.raises(Ros2InputError, match="PoseArray"):
        keypoints_in(mapping, mapping.clock(1.0), 3)


def test_a_stamp_is_rounded_to_the_nanosecond_and_an_invalid_one_is_refused() -> None:
    """Out: rounded as every other ROS 2 time (it was truncated: 2.9999999999999996 went out as 2.999999999 s)."""
    mapping = Ros2Mapping(Ros2Config())
    msg = mapping.ts.deserialize_cdr(keypoints_out(mapping, np.zeros((1, 3)), 2.9999999999999996, "recorder"),
                                     KEYPOINTS_TYPE)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (3, 0)
    msg.header.stamp.nanosec = 1_200_000_000
    with pytest.raises(Ros2InputError, match="PoseArray: header.stamp: nanosec 1200000000"):
        keypoints_in(mapping, bytes(mapping.ts.serialize_cdr(msg, KEYPOINTS_TYPE)), 1)
