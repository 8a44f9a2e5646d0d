"""The key expressions of the wire contract: one data key per message type, liveliness tokens."""

from __future__ import annotations

from .messages import ClassPosterior, ClockTick, DemoMarker, HumanPose, OccupancyGrid, Plan, RobotState
from .schema import Message

__all__ = ["SERVICES", "Keys"]

SERVICES = ("replayer", "predictor", "planner", "executor")


class Keys:
    """Key expressions under a prefix (default ``foresight``).

    Args:
        prefix: Key prefix without trailing ``/``.
    """

    def __init__(self, prefix: str = "foresight") -> None:
        self.prefix = prefix
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

    def data_keys(self) -> dict[str, type[Message]]:
        """Every data key expression and the one message type it carries."""
        return {
            self.pose: HumanPose,
            self.demo: DemoMarker,
            self.posterior: ClassPosterior,
            self.occupancy: OccupancyGrid,
            self.plan: Plan,
            self.robot_state: RobotState,
            self.clock: ClockTick,
        }
