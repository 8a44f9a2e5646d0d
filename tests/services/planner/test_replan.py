"""When the real-time planner starts a step (services/planner/replan.py)."""

from __future__ import annotations

import pytest

from services.planner.replan import ReplanTrigger


def test_event_mode_starts_on_new_prediction_departure_or_period() -> None:
    t = ReplanTrigger(period_s=0.5, mode="event")
    assert t.reason(0.0, None) == "first" and t.wait_s(0.0) == 0.0
    t.start(0.0, None, "first")
    assert t.reason(0.1, None) is None  # nothing new, period not over
    assert t.wait_s(0.1) == pytest.approx(0.4)
    assert t.reason(0.1, (0, -1, 7, 1.0)) == "occupancy"
    t.start(0.1, (0, -1, 7, 1.0), "occupancy")
    assert t.reason(0.2, (0, -1, 7, 1.0)) is None  # the same prediction again
    assert t.reason(0.2, (0, -1, 7, 1.0), departed=True) == "departure"
    assert t.reason(0.6, (0, -1, 7, 1.0)) == "period"
    assert t.newer_than_planned((0, -1, 8, 1.1)) and not t.newer_than_planned((0, -1, 7, 1.0))
    assert not t.newer_than_planned(None)
    t.start(0.6, (0, -1, 7, 1.0), "period")
    assert t.counts == {"first": 1, "occupancy": 1, "departure": 0, "period": 1}


def test_period_mode_ignores_new_input() -> None:
    t = ReplanTrigger(period_s=0.2, mode="period")
    t.start(1.0, None, "first")
    assert t.reason(1.1, (0, -1, 3, 0.0), departed=True) is None
    assert t.reason(1.2, (0, -1, 3, 0.0)) == "period"


@pytest.mark.parametrize(("period", "mode"), [(0.0, "event"), (-1.0, "period"), (0.5, "sometimes")])
def test_bad_settings_are_named(period: float, mode: str) -> None:
    with pytest.raises(ValueError, match="period_s|trigger"):
        ReplanTrigger(period, mode)



def test_the_periods_plan_lands_within_the_period_of_the_last_one() -> None:
    """The executor holds the robot once the newest plan is older than its stale limit (0.5 s, the period): a step
    started a whole period after the last one published its plan late whenever it planned longer than the last."""
    t = ReplanTrigger(period_s=0.5, mode="event")
    t.start(0.0, None, "first")  # published at 0.04 (planned 40 ms)
    assert t.reason(0.45, None, lead_s=0.04) is None
    assert t.reason(0.46, None, lead_s=0.04) == "period"  # published by 0.46 + 0.07 = 0.53 < 0.04 + 0.5
    assert t.wait_s(0.3, lead_s=0.04) == pytest.approx(0.16)
    assert t.lead(2.0) == 0.25  # a planner slower than half its period starts a step half a period after the last
    assert t.reason(0.25, None, lead_s=2.0) == "period" and t.reason(0.2, None, lead_s=2.0) is None
    paper = ReplanTrigger(period_s=0.5, mode="period")  # the paper's fixed period: step starts a period apart
    paper.start(0.0, None, "first")
    assert paper.reason(0.46, None, lead_s=0.04) is None and paper.reason(0.5, None, lead_s=0.04) == "period"
    assert paper.wait_s(0.3, lead_s=0.04) == pytest.approx(0.2)
