"""A run's record: what it publishes, collected live (:class:`RunRecorder`) or read back from its MCAP log.

The record keeps the plans and robot states in arrival order, every class posterior (lock-step: the last of each
tick), the poses, and the newest occupancy grid: the run's final prediction, which its interference is scored
against. The demo feeds it from its subscriber; ``foresight log table`` and :func:`recorder_from_log` from a log.

After Ctrl-C the demo stops the executor first, and the executor closes its log; the planner and predictor go on
publishing until they are stopped in turn. What the demo received meanwhile is not the run's: its summary (the
final prediction, the recognised class, the interference) differed from ``foresight log table`` of the same log.
:func:`recorder_from_log` replays the log's messages on the run's own keys into a :class:`RunRecorder`.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from shared.protocol import (
    ClassPosterior,
    HumanPose,
    Keys,
    Message,
    OccupancyGrid,
    Plan,
    ProtocolError,
    RobotState,
    decode,
)
from shared.recording.reader import DAMAGED, iter_messages
from shared.runtime import UserError

__all__ = ["ARRIVAL_KEY0", "RunRecorder", "keep_posterior", "recorder_from_log"]

ARRIVAL_KEY0 = 1 << 40
"""The first key of real-time (tick -1) posteriors in a posteriors-by-tick dict: above every tick."""


def keep_posterior(posteriors: dict[int, ClassPosterior], msg: ClassPosterior) -> None:
    """Keep a received posterior for ``scenario.posterior_for``: lock-step, the last of its tick; real time, every one.

    Real time stamps every message tick -1: keyed by their tick, each posterior replaced the one before, and the
    belief of every plan but the last (made before the newest posterior) came out empty in the demo's live table
    and summary. They are keyed by arrival there, from :data:`ARRIVAL_KEY0` (no tick reaches it: a run that mixed
    both kinds kept them apart; the newest arrival is still the largest key).
    """
    posteriors[msg.tick if msg.tick >= 0 else ARRIVAL_KEY0 + len(posteriors)] = msg


def _newness(grid: OccupancyGrid) -> tuple[int, float, int, int]:
    """Grids' order: the tick, then (real time: every tick -1) the stamp, the demonstration and the sample.

    The sample alone restarts with each demonstration of a real-time stream.
    """
    return grid.tick, grid.stamp, grid.demo_id, grid.index


class RunRecorder:
    """Collects what a run publishes (thread-safe; fed by a subscriber, no Zenoh in here)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.plans: list[Plan] = []
        self.plan_times: list[float] = []  # when each plan arrived (s, wall clock): which the executor adopted
        self.states: list[RobotState] = []
        self.final_occupancy: OccupancyGrid | None = None
        self.posteriors: dict[int, ClassPosterior] = {}
        self.poses: list[HumanPose] = []

    def on_message(self, msg: Message, received: float | None = None) -> None:
        """Feed one received message; ``received``: when (s, wall clock; default now: a log's is its log time)."""
        with self._lock:
            if isinstance(msg, Plan):
                self.plans.append(msg)
                self.plan_times.append(time.time() if received is None else received)
            elif isinstance(msg, RobotState):
                self.states.append(msg)
            elif isinstance(msg, OccupancyGrid):
                if self.final_occupancy is None or _newness(msg) >= _newness(self.final_occupancy):
                    self.final_occupancy = msg
            elif isinstance(msg, ClassPosterior):
                keep_posterior(self.posteriors, msg)
            elif isinstance(msg, HumanPose):
                self.poses.append(msg)

    def snapshot(self) -> tuple[list[Plan], list[RobotState], OccupancyGrid | None, dict[int, ClassPosterior]]:
        """Copies of what was recorded so far."""
        with self._lock:
            return list(self.plans), list(self.states), self.final_occupancy, dict(self.posteriors)

    def plan_arrivals(self) -> list[float]:
        """When each plan of :meth:`snapshot` arrived (``summarise``'s ``received``: the plans the executor adopted)."""
        with self._lock:
            return list(self.plan_times)

    def human_poses(self) -> list[HumanPose]:
        """The human's poses received so far, in time order."""
        with self._lock:
            return sorted(self.poses, key=lambda p: (p.stamp, p.index))


def recorder_from_log(path: Path, keys: Keys) -> RunRecorder | None:
    """What the log at ``path`` holds on the run's keys, as received; None if there is no readable log.

    Args:
        path: The run's MCAP (complete or cut short: read up to its end or damage).
        keys: The run's keys (its prefix).
    """
    types = {keys.plan, keys.robot_state, keys.occupancy, keys.posterior, keys.pose}
    expected = keys.data_keys()
    recorder = RunRecorder()
    try:
        for m in iter_messages(path):
            if m.topic in types:
                try:
                    recorder.on_message(decode(m.data, expected[m.topic]), m.log_time / 1e9)
                except ProtocolError:
                    continue  # only valid payloads are on a key's channel; be tolerant anyway
    except (UserError, OSError, *DAMAGED):
        return None
    return recorder
