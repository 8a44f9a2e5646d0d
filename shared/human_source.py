"""What a human source publishes: the human's poses and demonstration markers, the way the replayer and the tracker do.

Both keys with congestion control *block* (no pose or marker is dropped), counted as they go. The replayer streams a
recording, the tracker a live person's reaches (``shared.protocol.HUMAN_SOURCES``); consumers cannot tell them apart.
"""

from __future__ import annotations

from typing import Any

from shared.protocol import DemoMarker, HumanPose, Keys
from shared.transport import TypedPublisher

__all__ = ["HumanPublisher"]


class HumanPublisher:
    """Publishes ``HumanPose`` on ``keys.pose`` and ``DemoMarker`` on ``keys.demo``.

    Args:
        session: An open Zenoh session.
        keys: The key expressions.

    Attributes:
        poses, markers, starts: Poses, markers and start markers published so far.
    """

    def __init__(self, session: Any, keys: Keys) -> None:
        self._poses: TypedPublisher[HumanPose] = TypedPublisher(session, keys.pose, block=True)
        self._markers: TypedPublisher[DemoMarker] = TypedPublisher(session, keys.demo, block=True)
        self.poses = self.markers = self.starts = 0

    def matched(self) -> bool:
        """Whether both keys have a subscriber now (Zenoh's matching status): what is put is not lost."""
        return self._poses.matched() and self._markers.matched()

    def put(self, msg: HumanPose | DemoMarker) -> None:
        """Publish one pose or marker on its key."""
        if isinstance(msg, HumanPose):
            self._poses.put(msg)
            self.poses += 1
            return
        self._markers.put(msg)
        self.markers += 1
        self.starts += msg.event == "start"
