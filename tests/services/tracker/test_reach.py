"""When a reach begins and ends (services/tracker/reach.py), on the wrist's body-frame path alone."""

from __future__ import annotations

from dataclasses import replace

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


def test_the_rule_s_first_start_on_a_motion_from_rest_is_its_first_pose_s_sample() -> None:
    """``first_start``, what a trainer cuts a demonstration at (``foresight train --time-from tracker``): the sample of
    the first pose the tracker publishes, ``pre_s`` before the wrist is ``start_m`` from rest; None without a reach."""
    from services.tracker.reach import first_start

    wrist = _path((HOME, HOME, 0.5), (HOME, GOAL, 1.0), (GOAL, GOAL, 1.0))
    crossed = int(np.argmax(np.linalg.norm(wrist - HOME, axis=1) > RULE.start_m))
    assert first_start(wrist, RATE, RULE) == crossed - round(RULE.pre_s * RATE) > 0
    assert first_start(wrist[crossed - 3:], RATE, RULE) == 0  # its first pose before the motion's first sample
    assert first_start(_path((HOME, HOME + [0.05, 0, 0], 1.0)), RATE, RULE) is None


def test_a_recorded_demonstration_starts_where_the_tracker_starts_its_reach(tmp_path) -> None:
    """``recorded_start`` on a library demonstration is the sample of the first pose the tracker publishes for it,
    fed its keypoints after a person's rest (a review: 8-30 samples into the synthetic library's demonstrations)."""
    from services.tracker.core import TrackerConfig, TrackerCore
    from services.tracker.reach import recorded_start
    from shared.keypoints.library import read_keypoint_csv, write_keypoint_library
    from shared.library import MotionLibrary
    from shared.protocol import DemoMarker, HumanPose
    from shared.synthetic import generate_library

    lib = generate_library(n_classes=2, n_demos=2, seed=3)
    demo, rest = lib.demos[0], 45
    padded = np.concatenate([np.repeat(demo.features[:1], rest, 0), demo.features])
    one = MotionLibrary(class_names=lib.class_names, demos=[replace(demo, features=padded)], issues=[], source="x")
    write_keypoint_library(one, tmp_path)
    kd = read_keypoint_csv(tmp_path / f"{demo.class_name}.csv")[0]
    core, msgs = TrackerCore(TrackerConfig()), []
    for frame, pos in zip(kd.frames, kd.positions, strict=True):
        msgs += core.on_frame(float(frame) / RATE, kd.names, pos, int(frame)).messages
    live = {m.demo_id for m in msgs if isinstance(m, DemoMarker) and m.event == "start" and m.class_name == "live"}
    first = next(m for m in msgs if isinstance(m, HumanPose) and m.demo_id in live)
    start = recorded_start(demo.features, TrackerConfig())
    assert start == round(first.stamp * RATE) - rest > 0
