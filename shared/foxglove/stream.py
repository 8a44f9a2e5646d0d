"""The scene channels of a run, encoded: which message draws what, how often, and its bytes on the wire.

:class:`SceneStream` is shared by the two consumers of the scene: the executor's MCAP log
(:class:`shared.recording.writer.McapLog`) and the live view (``foresight view``, :mod:`services.view`).
Each received Foresight message that has a picture becomes one or more :class:`VizMessage` - the topic,
its schema as the file or the WebSocket advertises it, and the encoded message - built by a
:class:`~shared.foxglove.scene.SceneBuilder` and encoded by ``foxglove-sdk`` (protobuf) or as JSON (the
two plot-able messages of :mod:`shared.foxglove.charts`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from foxglove.messages import FrameTransforms, PointCloud, SceneUpdate

from shared.protocol import (
    ClassPosterior,
    DemoMarker,
    HumanKeypoints,
    HumanPose,
    Message,
    OccupancyGrid,
    Plan,
    RobotState,
)

from .charts import COSTS_SCHEMA, POSTERIOR_SCHEMA, costs_chart, posterior_chart
from .keypoints import keypoints_update
from .scene import SceneBuilder

__all__ = ["TOPICS", "DRAWS", "VizSchema", "VizMessage", "SceneStream", "SCHEMAS"]


@dataclass(frozen=True)
class VizSchema:
    """A scene channel's schema and message encoding, as an MCAP file or a WebSocket server declares them."""

    name: str
    encoding: str  # schema encoding: "protobuf" (a FileDescriptorSet) or "jsonschema"
    data: bytes
    message_encoding: str  # "protobuf" or "json"


@dataclass(frozen=True)
class VizMessage:
    """One encoded message of a scene channel."""

    topic: str
    data: bytes
    log_time: int  # ns; the receive time of the message it draws (one time base for everything drawn)

    @property
    def schema(self) -> VizSchema:
        """The channel's schema (:data:`SCHEMAS`)."""
        return SCHEMAS[self.topic]


def _proto(cls: Any) -> VizSchema:
    s = cls.get_schema()
    return VizSchema(s.name, s.encoding, bytes(s.data), "protobuf")


def _json(schema: dict[str, Any]) -> VizSchema:
    return VizSchema(schema["title"], "jsonschema", json.dumps(schema, separators=(",", ":")).encode(), "json")


SCHEMAS: dict[str, VizSchema] = {
    "/viz/scene": _proto(SceneUpdate),      # table and cups
    "/tf": _proto(FrameTransforms),         # world -> robot base, end effector
    "/viz/robot": _proto(SceneUpdate),      # robot collision spheres
    "/viz/occupancy": _proto(PointCloud),   # predicted occupancy: voxel centres, probability, colour
    "/viz/plan": _proto(SceneUpdate),       # candidate end-effector paths
    "/viz/human": _proto(SceneUpdate),      # human body segments
    "/viz/keypoints": _proto(SceneUpdate),  # a body tracker's points
    "/viz/posterior": _json(POSTERIOR_SCHEMA),
    "/viz/costs": _json(COSTS_SCHEMA),
}
"""Every scene channel: topic -> schema."""

TOPICS: dict[str, str] = {topic: s.name for topic, s in SCHEMAS.items()}
"""Every scene channel: topic -> schema name."""

_EVERY = frozenset({"/viz/plan", "/viz/posterior"})
"""Drawn for every message; the others at most once per ``viz_period_s`` of message time."""


DRAWS: dict[str, tuple[str, ...]] = {"/viz/plan": ("/viz/plan", "/viz/costs"), "/viz/robot": ("/viz/robot", "/tf"),
                                      "/viz/occupancy": ("/viz/occupancy",), "/viz/human": ("/viz/human",),
                                      "/viz/posterior": ("/viz/posterior",), "/viz/keypoints": ("/viz/keypoints",)}
"""The topics :meth:`SceneStream.draw` writes for each message kind (the topic :meth:`SceneStream.due` names)."""


def _kind(msg: Message) -> str | None:
    """The throttled topic that draws ``msg`` (None: nothing does)."""
    for cls, topic in ((Plan, "/viz/plan"), (RobotState, "/viz/robot"), (OccupancyGrid, "/viz/occupancy"),
                       (HumanPose, "/viz/human"), (ClassPosterior, "/viz/posterior"),
                       (HumanKeypoints, "/viz/keypoints")):
        if isinstance(msg, cls):
            return topic
    return None


class SceneStream:
    """Turns received messages into encoded scene messages, the occupancy, robot and human throttled.

    Not thread-safe: a caller receiving on several threads holds a lock around :meth:`due`/:meth:`mark`.

    Args:
        builder: Builds the scene messages.
        viz_period_s: Smallest time (message stamps) between two updates of the robot, the human or the
            occupancy; plans and posteriors are drawn every time.
    """

    def __init__(self, builder: SceneBuilder, viz_period_s: float = 0.2) -> None:
        self.builder = builder
        self.viz_period_s = viz_period_s
        self._last: dict[str, float] = {}

    def static(self, log_time: int) -> list[VizMessage]:
        """The table, the cups and the robot's base frame, stamped ``log_time`` (ns)."""
        t = log_time / 1e9
        return [VizMessage("/viz/scene", self.builder.static_scene(t).encode(), log_time),
                VizMessage("/tf", self.builder.base_transform(t).encode(), log_time)]

    def due(self, msg: Message) -> str | None:
        """The topic that would draw ``msg`` now (None: nothing draws it, or its topic was drawn too recently).

        Every human pose passes here, drawn or not: the builder keeps each demonstration's first as the human's
        placement reference (:meth:`SceneBuilder.note_pose`).
        """
        if isinstance(msg, HumanPose):
            self.builder.note_pose(msg)
        if isinstance(msg, DemoMarker):  # a demonstration's end or loss: its body greyed, never held back
            return "/viz/human" if msg.event in ("end", "lost") else None
        topic = _kind(msg)
        if topic is None or topic in _EVERY:
            return topic
        last, stamp = self._last.get(topic), float(getattr(msg, "stamp", 0.0))
        return topic if last is None or not 0.0 <= stamp - last < self.viz_period_s - 1e-9 else None

    def mark(self, topic: str, msg: Message) -> None:
        """Record that ``msg`` is drawn on ``topic`` (the next one of its kind waits ``viz_period_s``)."""
        if not isinstance(msg, DemoMarker):  # the end marker holds back no pose
            self._last[topic] = float(getattr(msg, "stamp", 0.0))

    def draw(self, msg: Message, log_time: int) -> list[VizMessage]:
        """The encoded scene messages of ``msg``, stamped with its receive time ``log_time`` (ns).

        One time base for everything drawn: the entities and transforms carry the receive time, never the
        message's own stamp, which is simulated time (seconds from 0, i.e. 1970) in lock-step runs.
        """
        b, t = self.builder, log_time / 1e9
        out: list[tuple[str, Any]] = []
        if isinstance(msg, Plan):
            out += [("/viz/plan", b.plan_paths(msg, stamp=t)), ("/viz/costs", costs_chart(msg, t))]
        elif isinstance(msg, RobotState):
            out += [("/viz/robot", b.robot_spheres(msg, stamp=t)), ("/tf", b.end_effector_transform(msg, stamp=t))]
        elif isinstance(msg, OccupancyGrid):
            out.append(("/viz/occupancy", b.occupancy_cloud(msg, stamp=t)))
        elif isinstance(msg, HumanPose):
            out.append(("/viz/human", b.human_body(msg, stamp=t)))
        elif isinstance(msg, DemoMarker):
            out.append(("/viz/human", b.human_ended(msg, stamp=t)))
        elif isinstance(msg, HumanKeypoints):
            update = keypoints_update(msg, b.placement_reference(), b.scene, t, self.viz_period_s)
            out.append(("/viz/keypoints", update))
        elif isinstance(msg, ClassPosterior):
            out.append(("/viz/posterior", posterior_chart(msg, t)))
        return [VizMessage(topic, _encode(obj), log_time) for topic, obj in out if obj is not None]


def _encode(obj: Any) -> bytes:
    if isinstance(obj, dict):
        return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()
    return obj.encode()
