"""ExecutorResult: the first step any goal is reached, and the first step each goal is."""

from __future__ import annotations

from services.executor.result import ExecutorResult


def test_each_goal_keeps_the_first_step_it_was_reached() -> None:
    r = ExecutorResult()
    assert r.note_reached(0, 10) and (r.reached, r.reached_step) == (True, 10)  # the first reach: logged once
    assert not r.note_reached(0, 11) and not r.note_reached(1, 17) and not r.note_reached(1, 18)
    assert r.reached_step == 10 and r.reached_steps == {0: 10, 1: 17}
