"""A run as its MCAP log holds it: the record a summary is made from when the run was cut short.

After Ctrl-C the demo stops the executor first, and the executor closes its log; the planner and predictor go on
publishing until they are stopped in turn. What the demo received meanwhile is not the run's: its summary (the
final prediction, the recognised class, the interference) differed from ``foresight log table`` of the same log.
:func:`recorder_from_log` replays the log's messages on the run's own keys into a :class:`RunRecorder`.
"""

from __future__ import annotations

from pathlib import Path

from shared.protocol import Keys, ProtocolError, decode
from shared.recording.reader import DAMAGED, iter_messages
from shared.runtime import UserError

from .scenario import RunRecorder

__all__ = ["recorder_from_log"]


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
                    recorder.on_message(decode(m.data, expected[m.topic]))
                except ProtocolError:
                    continue  # only valid payloads are on a key's channel; be tolerant anyway
    except (UserError, OSError, *DAMAGED):
        return None
    return recorder
