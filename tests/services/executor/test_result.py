"""ExecutorResult: the first step any goal is reached, and the first step each goal is."""

from __future__ import annotations

from services.executor.result import ExecutorResult


def test_each_goal_keeps_the_first_step_it_was_reached() -> None:
    r = ExecutorResult()
    assert r.note_reached(0, 10) and (r.reached, r.reached_step) == (True, 10)  # the first reach: logged once
    assert not r.note_reached(0, 11) and not r.note_reached(1, 17) and not r.note_reached(1, 18)
    assert r.reached_step == 10 and r.reached_steps == {0: 10, 1: 17}


def test_the_closing_words_name_the_last_goal_and_whether_it_was_reached() -> None:
    """The closing line put the first reach of any goal beside the last goal: "goal 1 reached during step 9" where
    only goal 0 had been reached."""
    from services.executor.result import ExecutorResult

    r = ExecutorResult(goal_per_step=[0] * 10 + [1] * 10)
    assert r.final_goal() == "goal 1 not reached"
    r.note_reached(0, 9)
    assert r.final_goal() == "goal 1 not reached (goal 0 was, during step 9)"
    r.note_reached(1, 17)
    assert r.final_goal() == "goal 1 reached during step 17" and r.reached_step == 9
    assert ExecutorResult().final_goal() == "goal none"
