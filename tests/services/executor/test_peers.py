"""The executor's words when a service of the run comes and goes (``services.executor.peers``)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from services.executor.config import ExecutorConfig
from services.executor.core import ArmLimits, ExecutorCore
from services.executor.peers import PeerWatch


def _core(config: ExecutorConfig) -> ExecutorCore:
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    return ExecutorCore(limits, np.zeros(1), config)


def test_a_recording_s_stream_ending_is_said_only_after_its_end_marker(caplog: pytest.LogCaptureFixture) -> None:
    """The log's reading of a lost token is the core's own: a replayer gone mid-demonstration is a fault however
    often its loss is told, and only one gone after its end marker 'ended its stream' (the log restated the rule
    without the end marker and said so on a second loss mid-demonstration)."""
    config = ExecutorConfig(mode="realtime")
    core, watch = _core(config), PeerWatch(config)
    with caplog.at_level(logging.INFO, logger="foresight.executor"):
        core.note_demonstration("start", 1, 100)
        watch.note("replayer", False, core)
        watch.note("replayer", False, core)
    said = [r.getMessage() for r in caplog.records]
    assert said == ["executor: replayer is gone: holding the robot"], said
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="foresight.executor"):
        watch.note("replayer", True, core)
        core.note_demonstration("end", 1, 100)
        watch.note("replayer", False, core)
    said = [r.getMessage() for r in caplog.records]
    assert said == ["executor: replayer is back",
                    "executor: replayer ended its stream after the demonstration's end: the robot goes on"], said
