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

