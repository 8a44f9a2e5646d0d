"""The key expressions of the wire contract: one data key per message type, liveliness tokens."""

from __future__ import annotations

from .messages import ClassPosterior, ClockTick, DemoMarker, HumanKeypoints, HumanPose, OccupancyGrid, Plan, RobotState
from .schema import Message

__all__ = ["SERVICES", "HUMAN_SOURCES", "SENSOR", "ROUTES", "Keys"]

SERVICES = ("replayer", "tracker", "predictor", "planner", "executor")
"""Foresight's services: each is a role of the access control and declares a liveliness token of its name."""

HUMAN_SOURCES = ("replayer", "tracker")
"""The services that publish the human (poses and markers): a recording, or a live person through the tracker.
A deployment runs one of them; the contract allows either."""

SENSOR = "sensor"
"""The role of a body tracker's driver (and of ``foresight tracker --from``'s player): it publishes keypoints only."""

ROUTES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "keypoints": ((SENSOR,), ("tracker", "executor")),
    "pose": (HUMAN_SOURCES, ("predictor", "planner", "executor")),
    "demo": (HUMAN_SOURCES, ("predictor", "planner", "executor")),
    "posterior": (("predictor",), ("executor",)),
    "occupancy": (("predictor",), ("planner", "executor")),
    "plan": (("planner",), ("executor",)),
    "robot_state": (("executor",), ("planner", "executor")),
    "clock": (("executor",), ("replayer", "planner", "executor")),
}
"""Who publishes and who subscribes to each data key (an attribute of :class:`Keys`): ``(owners, consumers)``.

One service owns each key, except the human's, which either human source publishes; keypoints come from a
sensor. The executor consumes every key, its own included (its MCAP log subscribes to ``<prefix>/**``).
Displays and tools read as observers. The access control of :mod:`shared.security.acl` is generated
from this table, and docs/protocol.md's key table states it.
"""


class Keys:
    """Key expressions under a prefix (default ``foresight``).

    Args:
        prefix: Key prefix without trailing ``/``.
    """

    def __init__(self, prefix: str = "foresight") -> None:
        self.prefix = prefix
        self.keypoints = f"{prefix}/sensor/keypoints"
        self.pose = f"{prefix}/human/pose"
        self.demo = f"{prefix}/human/demo"
        self.posterior = f"{prefix}/prediction/posterior"
        self.occupancy = f"{prefix}/prediction/occupancy"
        self.plan = f"{prefix}/planner/plan"
        self.robot_state = f"{prefix}/robot/state"
        self.clock = f"{prefix}/clock/tick"
        self.alive_all = f"{prefix}/alive/*"
        self.human_all = f"{prefix}/human/*"  # poses and markers in one ordered subscription

    def alive(self, service: str) -> str:
        """Liveliness token key of a service."""
        return f"{self.prefix}/alive/{service}"

    def routes(self) -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
        """Every data key expression with its owner and consumers (:data:`ROUTES`)."""
        return {getattr(self, attr): route for attr, route in ROUTES.items()}

    def data_keys(self) -> dict[str, type[Message]]:
        """Every data key expression and the one message type it carries."""
        return {
            self.keypoints: HumanKeypoints,
            self.pose: HumanPose,
            self.demo: DemoMarker,
            self.posterior: ClassPosterior,
            self.occupancy: OccupancyGrid,
            self.plan: Plan,
            self.robot_state: RobotState,
            self.clock: ClockTick,
        }
