"""When a reach begins and ends (services/tracker/reach.py), on the wrist's body-frame path alone."""

from __future__ import annotations

import numpy as np

from services.tracker.reach import ReachDetector, ReachRule

RATE = 30.0
HOME, GOAL = np.array([0.2, -0.2, -0.3]), np.array([0.6, 0.1, 0.0])
RULE = ReachRule(end_s=1.0)  # the tracker's end_s


def _path(*legs: tuple[np.ndarray, np.ndarray, float]) -> np.ndarray:
    """The wrist moving linearly from each leg's first point to its second over its seconds, at 30 Hz."""
    return np.concatenate([np.linspace(a, b, max(1, int(s * RATE)), endpoint=False) for a, b, s in legs])


def _events(wrist: np.ndarray, rule: ReachRule = RULE) -> list[tuple[str, float]]:
    det = ReachDetector(rule)
    out = []
    for i, w in enumerate(wrist):
        ev = det.update(w, i / RATE)
        if ev is not None:
            out.append((ev.event, round(i / RATE, 2)))
    return out


def test_the_way_back_from_a_goal_is_no_reach_and_the_next_reach_starts_from_rest() -> None:
    """The goal became the rest position: the way back was published as a reach of its own, recognised as some class
    with full confidence (a review's live run)."""
    wrist = _path((HOME, HOME, 1.5), (HOME, GOAL, 1.0), (GOAL, GOAL, 1.5),   # rest, reach, hold at the goal
                  (GOAL, HOME, 1.0), (HOME, HOME, 1.5),                       # back home, rest
                  (HOME, GOAL, 1.0), (GOAL, GOAL, 1.5))                       # a second reach
    events = _events(wrist)
    assert [e for e, _ in events] == ["start", "end", "start", "end"], events
    assert 1.5 < events[0][1] < 2.5 and events[2][1] > 6.5  # the second start is the second reach, not the return


def test_a_hand_that_stays_away_learns_its_rest_again_after_max_s() -> None:
    """Never back home: after max_s away the rest is learnt where the hand is, and a reach from there starts."""
    rule = ReachRule(end_s=1.0, max_s=3.0)
    wrist = _path((HOME, HOME, 1.5), (HOME, GOAL, 1.0), (GOAL, GOAL, 6.0), (GOAL, HOME + [0, 0, 0.5], 1.0),
                  (HOME + [0, 0, 0.5], HOME + [0, 0, 0.5], 1.5))
    assert [e for e, _ in _events(wrist, rule)] == ["start", "end", "start", "end"]


def test_a_hand_put_down_off_its_old_rest_takes_that_as_its_rest() -> None:
    """Back from the goal but 12 cm off its old rest, the hand stayed 'returning' for max_s: the next reaches were
    missed (a review of the returning state)."""
    near = HOME + [0.0, 0.12, 0.0]
    wrist = _path((HOME, HOME, 1.5), (HOME, GOAL, 1.0), (GOAL, GOAL, 1.5), (GOAL, near, 1.0), (near, near, 1.5),
                  (near, GOAL, 1.0), (GOAL, GOAL, 1.5))
    assert [e for e, _ in _events(wrist)] == ["start", "end", "start", "end"]
