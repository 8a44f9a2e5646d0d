"""The executor's config: a lock-step rate of RobotStates that the steps cannot keep is said, not silently changed."""

from __future__ import annotations

import pytest

from services.executor.config import ExecutorConfig


@pytest.mark.parametrize("rate", [1.0, 2.6, 7.0])
def test_a_lockstep_rate_rounded_to_whole_states_per_step_is_named(rate: float) -> None:
    """1, 2.6 and 7 Hz all published at 5 Hz with 0.2 s steps, and nothing said so."""
    cfg = ExecutorConfig(mode="lockstep", step_period_s=0.2, state_rate_hz=rate)
    assert cfg.substeps == 1
    assert cfg.state_rate_note() == (f"executor: lock-step publishes 1 RobotState(s) per 0.2 s step, 5 Hz of simulated "
                                     f"time, not state_rate_hz {rate:g} (a whole number per step, at least 1)")


@pytest.mark.parametrize(("mode", "rate"), [("lockstep", 50.0), ("lockstep", 5.0), ("realtime", 2.6)])
def test_a_rate_that_is_kept_gives_no_note(mode: str, rate: float) -> None:
    assert ExecutorConfig(mode=mode, step_period_s=0.2, state_rate_hz=rate).state_rate_note() == ""
