"""The ``[tracker]`` section: where the keypoints come from, and the core's thresholds (same table)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from services.ros2.domain import UNREADABLE_DOMAIN, check_domain_id, ros_domain_id
from services.ros2.wire import topic_problem
from shared.config import LOG_LEVELS, ConfigError, nested, opt
from shared.config_names import check_services
from shared.keypoints.layouts import load_layout
from shared.protocol import SERVICES

from .core import TrackerConfig

__all__ = ["TrackerServiceConfig", "PlaybackConfig", "INPUTS"]

INPUTS = ("zenoh", "ros2")
"""Where keypoint frames come from: ``HumanKeypoints`` on Foresight's key, or a ROS 2 ``PoseArray`` topic."""


@dataclass
class PlaybackConfig:
    """How ``--from FILE`` plays a keypoint recording: a person at rest, the reach, rest again, then out of view."""

    rate_hz: float = opt(30.0, help="--from: the recording's frame rate (frame n is played n / rate_hz s in)")
    lead_s: float = opt(1.5, help="--from: the first frame of each demonstration is held this long before it plays "
                        "(the person stands at rest; the tracker learns where the hand rests)")
    hold_s: float = opt(1.5, help="--from: the last frame is held this long after (the hand at the goal: the reach "
                        "ends)")
    gap_s: float = opt(1.0, help="--from: no frames for this long between demonstrations (the person out of view: "
                       "the tracker starts afresh)")
    loop: bool = opt(False, help="--from: start over after the last demonstration (until stopped)")

    def validate(self) -> None:
        """Check ranges; raises ConfigError naming the option."""
        if not (self.rate_hz > 0 and math.isfinite(self.rate_hz)):
            raise ConfigError(f"tracker.rate_hz: must be > 0, got {self.rate_hz}")
        for name in ("lead_s", "hold_s", "gap_s"):
            v = getattr(self, name)
            if not (v >= 0 and math.isfinite(v)):
                raise ConfigError(f"tracker.{name}: must be a finite number >= 0, got {v}")


@dataclass
class TrackerServiceConfig:
    """Options of ``foresight tracker`` (``[tracker]``): the service's own, the core's and the playback's."""

    input: str = opt("zenoh", choices=INPUTS, help="zenoh: HumanKeypoints on <prefix>/sensor/keypoints (a sensor "
                     "driver, --from); ros2: geometry_msgs/PoseArray on --ros2-topic over rmw_zenoh "
                     "(docs/keypoints.md)")
    from_file: Path | None = opt(None, help="play this keypoint recording (a <class>.csv of a keypoint library) in "
                                 "real time as the sensor would, on the keypoints key; the tracker takes it from "
                                 "there (--from FILE)")
    ros2_topic: str = opt("/foresight/keypoints", help="input ros2: the PoseArray topic")
    ros2_domain_id: int = opt(default_factory=lambda: ros_domain_id(), help="input ros2: the ROS 2 domain id "
                              "(default: $ROS_DOMAIN_ID, else 0)")
    ros2_points: list[str] = opt(default_factory=list, help="input ros2: the name of each pose of the PoseArray, in "
                                 "order (comma-separated; empty: the layout's own order, e.g. COCO's 17 keypoints "
                                 "by id for coco17)")
    stop_with: list[str] = opt(default_factory=list, help="end when one of these services (e.g. executor) "
                               "disappears after it was seen (comma-separated; how a compose run ends)")
    wait_for: list[str] = opt(default_factory=list, help="--from: wait for the liveliness tokens of these services "
                              "(e.g. executor) before playing")
    wait_timeout: float = opt(300.0, help="seconds to wait for --wait-for services before playing anyway")
    log_level: str = opt("INFO", choices=LOG_LEVELS, help="log level")
    tracker: TrackerConfig = nested(TrackerConfig, inline=True, help="the tracker's fit, checks, smoothing and reach "
                                    "rule")
    playback: PlaybackConfig = nested(PlaybackConfig, inline=True, help="how --from plays a recording")

    def validate(self) -> None:
        """Check the core's and the playback's options and the service's own."""
        self.tracker.validate()
        self.playback.validate()
        if self.from_file is not None and self.input != "zenoh":
            raise ConfigError("tracker.from_file: plays on the keypoints key, so it needs tracker.input = zenoh")
        if self.from_file is not None and not Path(self.from_file).is_file():
            raise ConfigError(f"tracker.from_file: {self.from_file} is not a file (a <class>.csv of a keypoint "
                              "library: foresight library to-keypoints LIB --out DIR)")
        problem = topic_problem(self.ros2_topic)
        if problem:
            raise ConfigError(f"tracker.ros2_topic: {problem}")
        if self.input == "ros2" or self.ros2_domain_id != UNREADABLE_DOMAIN:  # the shell's ROS_DOMAIN_ID: if used
            check_domain_id(self.ros2_domain_id, "tracker.ros2_domain_id", "--ros2-domain-id")
        if len(set(self.ros2_points)) != len(self.ros2_points):
            raise ConfigError(f"tracker.ros2_points: names repeated: {self.ros2_points}")
        layout = load_layout(self.tracker.layout)
        unknown = layout.unknown(self.ros2_points)
        if unknown:  # every frame would be refused for its names
            raise ConfigError(f"tracker.ros2_points: {unknown} are not points of the layout {layout.name} (e.g. "
                              f"{', '.join(layout.source_names[:4])})")
        if self.ros2_points and (lacking := layout.lacking(self.ros2_points)):  # every frame refused as missing
            raise ConfigError(f"tracker.ros2_points: they cannot form the required {lacking} of the layout "
                              f"{layout.name} (tracker.layout)")
        for name in ("stop_with", "wait_for"):
            check_services(getattr(self, name), f"tracker.{name}", [s for s in SERVICES if s != "tracker"])
        if self.wait_timeout < 0:
            raise ConfigError(f"tracker.wait_timeout: must be >= 0, got {self.wait_timeout}")
