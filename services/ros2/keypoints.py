"""A body tracker's keypoints as a ROS 2 ``geometry_msgs/msg/PoseArray`` (pure: the ``rosbags`` type store).

ROS 2 has no standard message for a skeleton; a ``PoseArray`` is what skeleton trackers' ROS 2 drivers and
bridges commonly publish when they give no message of their own, and every ROS 2 tool shows it (RViz draws it).
The convention the tracker takes (docs/keypoints.md):

* ``poses[i].position`` is the point named ``names[i]``, in the tracker's configured order (``[tracker]
  ros2_points``; default: the layout's own order, :attr:`shared.keypoints.layouts.Layout.native_order`: COCO's
  17 keypoints by id for ``coco17``, MediaPipe's 33 landmarks for ``mediapipe33``); the orientations are ignored;
* a point the sensor lost is ``NaN`` in all three coordinates (a ``PoseArray`` cannot leave one out);
* ``header.stamp`` is the frame's time, ``header.frame_id`` its coordinate frame (the tracker refuses another
  than its ``frame_id``); a zero stamp means "now" (the time the sample arrived).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .core import KEYPOINTS_TYPE, Ros2InputError, Ros2Mapping, seconds_in, time_msg

__all__ = ["keypoints_in", "keypoints_out"]


def keypoints_in(mapping: Ros2Mapping, payload: bytes, n_points: int) -> tuple[float, str, np.ndarray]:
    """A ``PoseArray`` of ``n_points`` keypoints: ``(stamp s, frame_id, positions (n_points, 3))``; stamp 0: unset.

    Raises:
        Ros2InputError: Not a PoseArray's CDR, or another number of poses than ``n_points``.
    """
    msg = mapping.decode(payload, KEYPOINTS_TYPE)
    if len(msg.poses) != n_points:
        raise Ros2InputError(f"PoseArray: {len(msg.poses)} poses, the tracker's point order has {n_points} "
                             "([tracker] ros2_points)")
    positions = np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses], dtype=np.float64)
    return seconds_in(msg.header.stamp, "PoseArray: header.stamp"), str(msg.header.frame_id), positions.reshape(-1, 3)


def keypoints_out(mapping: Ros2Mapping, positions: np.ndarray, stamp: float, frame_id: str) -> bytes:
    """``positions (J, 3)`` (NaN where lost) as a ``PoseArray`` at ``stamp`` (s) in ``frame_id`` (no rotations)."""
    t = mapping.ts.types
    header = t["std_msgs/msg/Header"](stamp=time_msg(mapping.ts, stamp), frame_id=frame_id)

    def pose(p: np.ndarray) -> Any:
        return t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]),
                                                                                   z=float(p[2])),
                                           orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))

    msg = t[KEYPOINTS_TYPE](header=header, poses=[pose(p) for p in np.asarray(positions, dtype=np.float64)])
    return bytes(mapping.ts.serialize_cdr(msg, KEYPOINTS_TYPE))
