"""Per-event DEBUG, periodic INFO summary (issue 24: the planner's INFO line per plan)."""

from __future__ import annotations

import logging

import pytest

from shared.log_summary import PeriodicSummary


def test_one_line_per_period_with_counts(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    summary = PeriodicSummary(logging.getLogger("t.summary"), "planner: plans", period_s=10.0, clock=lambda: now[0])
    with caplog.at_level(logging.INFO, logger="t.summary"):
        for i in range(30):  # 30 events over 15 s: one line at 10 s, the rest at flush
            now[0] = i * 0.5
            summary.add(20.0 + i, "chose red_cup" if i % 3 else "chose blue_cup")
        assert len(caplog.records) == 1
        first = caplog.records[0].getMessage()
        assert first.startswith("planner: plans: 21 in the last 10.0 s") and "40 ms max" in first
        assert "chose red_cup 14, chose blue_cup 7" in first
        summary.flush()
        summary.flush()  # nothing new: no line
    assert len(caplog.records) == 2
    assert caplog.records[1].getMessage().startswith("planner: plans: 9 in the last 4.5 s")
