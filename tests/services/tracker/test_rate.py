"""FrameRate: the sensor's period from its frames' intervals, and how many frames a gap lacks."""

from __future__ import annotations

import pytest

from services.tracker.rate import FrameRate

P = 1 / 30


def _rate(intervals: list[float]) -> FrameRate:
    rate = FrameRate()
    for dt in intervals:
        rate.add(dt)
    return rate


def test_intervals_of_whole_periods_are_the_sensors_and_a_gap_in_them_is_bridged() -> None:
    """Frames lost regularly (one, two periods): not steady before, and no gap was ever bridged."""
    rate = _rate([P, P, 2 * P, P, P, 2 * P, 3 * P])
    assert rate.period == pytest.approx(P) and rate.steady()
    assert rate.missed(3 * P) == 2 and rate.missed(3 * P, dropped=1) == 1  # the sensor's numbers bound it
    assert not rate.regular(2.5 * P) and rate.regular(2.2 * P) and rate.regular(1.4 * P) and not rate.regular(0.4 * P)
    odd = _rate([P, P, 2.5 * P, P, P])  # an interval of no whole number of periods among the last three
    assert not odd.steady() and odd.missed(3 * P) == 0


def test_frame_numbers_prove_a_drop_the_stamps_agree_with() -> None:
    rate = _rate([P, P, 2.5 * P, P, P])  # not steady: the stamps alone bridge nothing
    assert rate.missed(3 * P, dropped=2) == 2  # three periods, two frames lost: as the sensor says
    assert rate.missed(3 * P, dropped=20) == 0  # numbers the stamps do not bear out (1.4 ms a frame): not taken
    assert rate.missed(P, dropped=0) == 0 and FrameRate().missed(3 * P, dropped=2) == 0  # no period known yet


def test_a_burst_sets_a_period_of_its_own_only_after_a_window_of_it() -> None:
    rate = _rate([P] * 15 + [0.001] * 5)  # a backlog flushed 1 ms apart: left out
    assert rate.period == pytest.approx(P)
    rate = _rate([P] * 15 + [P / 4] * 15)  # a sensor switched to 120 Hz: a window of it in a row
    assert rate.period == pytest.approx(P / 4) and rate.hz == pytest.approx(120)
