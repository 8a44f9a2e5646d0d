"""Demonstrations: the reaches and the person seen at rest, as the predictor and the executor read them."""

from __future__ import annotations

import numpy as np

from services.executor.config import ExecutorConfig
from services.executor.core import ArmLimits, ExecutorCore
from services.tracker.core import TrackerConfig, TrackerCore
from services.tracker.demos import LIVE_CLASS, REST_POSES, reach_messages
from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES
from shared.protocol import AT_REST, DemoMarker, HumanPose, Plan

MODEL = HumanModel()
NAMES = list(POINT_NAMES)
RATE = 30.0


def _feed(core: TrackerCore, feats: np.ndarray, t0: float = 0.0) -> list:
    """Every message of ``feats`` ``(T, 12)`` played as keypoints at 30 Hz from ``t0`` s."""
    out = []
    for i, p in enumerate(MODEL.joint_positions(feats)):
        out += core.on_frame(t0 + i / RATE, NAMES, p).messages
    return out


def _markers(msgs: list) -> list[tuple[str, int, str]]:
    return [(m.event, m.demo_id, m.class_name) for m in msgs if isinstance(m, DemoMarker)]


def test_a_person_standing_still_is_published_once_at_rest(reach) -> None:
    """Before, a person who stood still gave nothing, and the robot held until their first reach."""
    core = TrackerCore()
    still = _feed(core, np.repeat(reach[:1], 90, 0))  # 3 s at rest
    assert _markers(still) == [("start", 0, AT_REST), ("end", 0, AT_REST)]
    poses = [m for m in still if isinstance(m, HumanPose)]
    assert 1 <= len(poses) <= REST_POSES and [p.index for p in poses] == list(range(len(poses)))
    assert still[-1].n_samples == len(poses) and all(p.demo_id == 0 for p in poses)
    assert abs(poses[-1].stamp - core.config.rest_s) <= 1.5 / RATE  # said as soon as the rest is learnt
    assert np.allclose([p.features for p in poses], reach[0], atol=0.02)  # where the person stands
    assert core.demos.rests == 1 and core.demos.reaches == 0


def test_the_reach_after_it_is_a_demonstration_of_its_own_and_unchanged(reach) -> None:
    core, plain = TrackerCore(), TrackerCore(TrackerConfig(announce_rest=False))
    msgs, without = _feed(core, reach), _feed(plain, reach)
    assert _markers(msgs)[:2] == [("start", 0, AT_REST), ("end", 0, AT_REST)]
    assert _markers(msgs)[2:] == [("start", 1, LIVE_CLASS), ("end", 1, LIVE_CLASS)]
    assert _markers(without) == [("start", 0, LIVE_CLASS), ("end", 0, LIVE_CLASS)]  # the option turns it off
    got, want = reach_messages(msgs, set()), without
    assert [type(m) for m in got] == [type(m) for m in want]  # the reach's poses: the same, but for its number
    assert np.array_equal([m.features for m in got if isinstance(m, HumanPose)],
                          [m.features for m in want if isinstance(m, HumanPose)])


def test_after_a_lost_reach_the_person_seen_again_at_rest_lets_the_robot_go_on(reach) -> None:
    """The person lost mid-reach, then back in view at rest: the executor held until their next reach (the left-alone
    item of the last note). Now the tracker publishes them at rest, the predictor predicts from there, and the robot
    goes on around that prediction."""
    core = TrackerCore()
    moving = next(i for i in range(30, len(reach)) if np.abs(reach[i] - reach[0]).max() > 0.2)
    msgs = _feed(core, reach[:moving + 10])  # at rest, then the reach under way ...
    back = 2.0 + (moving + 10) / RATE  # ... the person out of view for 2 s, then back, standing still
    msgs += _feed(core, np.repeat(reach[:1], 60, 0), t0=back)
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST), ("start", 1, LIVE_CLASS),
                              ("lost", 1, LIVE_CLASS), ("start", 2, AT_REST), ("end", 2, AT_REST)]
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    executor = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=10.0))
    executor.adopt(_plan())
    for m in msgs:  # the predictor answers each pose with its occupancy
        if isinstance(m, DemoMarker):
            executor.note_demonstration(m.event, m.demo_id, m.n_samples)
        else:
            executor.note_occupancy()
            executor.note_occupancy_of(m.demo_id, m.index)
        if isinstance(m, DemoMarker) and m.event == "lost":
            assert "lost mid-reach" in executor.stale_reason()
    assert executor.stale_reason() == "" and executor.human_ended
    assert core.demos.rests == 2 and core.demos.lost == 1


def test_a_reach_ended_at_rest_is_not_followed_by_another_rest(reach) -> None:
    """Once per track: the person back at rest after a reach is that reach's end (the executor goes on with it)."""
    core = TrackerCore()
    msgs = _feed(core, np.concatenate([reach, reach[::-1], np.repeat(reach[:1], 90, 0)]))  # out, back, still
    assert [e for e in _markers(msgs) if e[2] == AT_REST] == [("start", 0, AT_REST), ("end", 0, AT_REST)]
    assert core.demos.reaches >= 1 and core.demos.rests == 1


def test_a_track_begun_mid_motion_publishes_no_rest_of_a_moving_hand_and_its_stamps_never_go_back(reach) -> None:
    """A review: a track that began as the hand moved published a 'rest' of the moving hand (15 cm) on the frame its
    reach started, and the reach's first poses repeated the rest's, stamped before its end (1.0 s, then 0.7 s)."""
    from services.tracker.reach import body_wrist

    for k in (30, 35, 40, 45):  # the recording's rest is its first 30 frames: these begin as the hand moves
        msgs = _feed(TrackerCore(), reach[k:])
        rest = {m.demo_id for m in msgs if isinstance(m, DemoMarker) and m.class_name == AT_REST}
        wrists = np.array([body_wrist(MODEL.joint_positions(m.features)) for m in msgs
                           if isinstance(m, HumanPose) and m.demo_id in rest]).reshape(-1, 3)
        assert not len(wrists) or np.ptp(wrists, axis=0).max() < 0.03, k
        stamps = [m.stamp for m in msgs if isinstance(m, HumanPose)]
        assert stamps == sorted(stamps), k
        assert ("start", 0, LIVE_CLASS) in _markers(msgs) or rest, k


def _plan() -> Plan:
    traj = np.linspace(0.0, 0.9, 51)[None, :, None].astype(np.float32)
    return Plan(stamp=0.0, tick=-1, step=0, goal_names=["g"], joint_names=["a"], dt=0.1, chosen=0, planning_ms=1.0,
                occupancy_tick=-1, occupancy_index=0, trajectories=traj, cost_smoothness=np.zeros(1),
                cost_obstacle=np.zeros(1), cost_human=np.zeros(1), cost_total=np.zeros(1), valid=np.ones(1, bool))
