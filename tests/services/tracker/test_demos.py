"""Demonstrations: the reaches and the person seen at rest, as the predictor and the executor read them."""

from __future__ import annotations

import numpy as np
import pytest

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
            assert "the tracker lost the person (demonstration 1" in executor.stale_reason()
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


# -- the person no longer where the last demonstration showed them -------------------------------------------------

PELVIS_X, PELVIS_YAW = 0, 3


def _executor_after(msgs: list) -> ExecutorCore:
    """An executor fed ``msgs``, the predictor answering each pose with its occupancy."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    executor = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=100.0))
    executor.adopt(_plan())
    for m in msgs:
        if isinstance(m, DemoMarker):
            executor.note_demonstration(m.event, m.demo_id, m.n_samples)
        else:
            executor.note_occupancy()
            executor.note_occupancy_of(m.demo_id, m.index)
    return executor


def _walk(start: np.ndarray, feature: int, by: float, n: int) -> np.ndarray:
    """``(n, 12)``: ``start`` with one feature going smoothly by ``by`` over ``n`` frames (the arm still)."""
    out = np.repeat(start[None], n, 0)
    out[:, feature] += by * 0.5 * (1 - np.cos(np.linspace(0.0, np.pi, n)))
    return out


def test_a_person_out_of_view_after_being_seen_at_rest_is_lost(reach) -> None:
    """Once the person at rest had been said, their leaving the view said nothing: the executor went on around the
    old prediction, nobody watching (the last note's safety gap)."""
    core = TrackerCore()
    msgs = _feed(core, np.repeat(reach[:1], 60, 0))
    executor = _executor_after(msgs)
    assert executor.stale_reason() == ""  # seen at rest: the robot goes on
    out = []
    for t in (4.0, 4.0 + 1 / RATE):  # 2 s later (out of view meanwhile): a leap the next frame confirms
        out += core.on_frame(t, NAMES, MODEL.joint_positions(reach[0])).messages
    assert _markers(out) == [("lost", 0, AT_REST)] and out[0].stamp == 59 / RATE  # at the last frame seen
    executor = _executor_after(msgs + out)
    assert "the tracker lost the person (demonstration 0" in executor.stale_reason()
    back = out + _feed(core, np.repeat(reach[:1], 60, 0), t0=4.0 + 2 / RATE)
    assert _markers(back)[1:] == [("start", 1, AT_REST), ("end", 1, AT_REST)]  # seen again: said again
    assert _executor_after(msgs + back).stale_reason() == ""
    assert core.demos.unseen == 1 and core.demos.lost == 0  # no reach was under way


def test_a_person_walking_away_with_the_arm_still_is_lost_and_said_again_where_they_stop(reach) -> None:
    """The reach rule watches the wrist in the body's frame: walking off with the arm still was no event, and the
    robot went on around the prediction of where the person had stood."""
    core = TrackerCore()
    still = np.repeat(reach[:1], 60, 0)
    away = _walk(reach[0], PELVIS_X, 0.6, 45)  # 0.6 m in 1.5 s
    there = np.repeat(away[-1:], 75, 0)
    msgs = _feed(core, np.concatenate([still, away, there]))
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST), ("lost", 0, AT_REST),
                              ("start", 1, AT_REST), ("end", 1, AT_REST)]
    lost = next(m for m in msgs if isinstance(m, DemoMarker) and m.event == "lost")
    moved = next(i for i, f in enumerate(away) if f[PELVIS_X] - reach[0][PELVIS_X] > 0.10)
    assert 0 <= lost.stamp - (60 + moved) / RATE <= 5 / RATE  # as the pelvis passes 10 cm (the smoothing lags)
    again = [m for m in msgs if isinstance(m, HumanPose) and m.demo_id == 1]
    assert np.allclose([p.features[PELVIS_X] for p in again], away[-1][PELVIS_X], atol=0.02)  # where they stopped
    assert again[0].stamp >= (60 + 45) / RATE  # not at a place of the walk: the body stands still first
    assert _executor_after(msgs[:msgs.index(lost) + 1]).stale_reason().startswith("the tracker lost the person")
    assert _executor_after(msgs).stale_reason() == ""


def test_a_person_turning_round_in_place_is_lost(reach) -> None:
    core = TrackerCore()
    msgs = _feed(core, np.concatenate([np.repeat(reach[:1], 60, 0), _walk(reach[0], PELVIS_YAW, np.pi / 2, 30)]))
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST), ("lost", 0, AT_REST)]


def test_a_person_standing_still_under_sensor_noise_is_said_once_and_never_lost(reach) -> None:
    """2 cm of noise per axis on every keypoint (a depth camera's skeleton), 10 s: the smoothed body stays put."""
    rng = np.random.default_rng(0)
    core = TrackerCore()
    joints = MODEL.joint_positions(np.repeat(reach[:1], 300, 0))
    msgs = []
    for i, p in enumerate(joints):
        msgs += core.on_frame(i / RATE, NAMES, p + rng.normal(0.0, 0.02, p.shape)).messages
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST)]


def test_a_hand_going_back_from_a_reach_s_goal_is_no_move(reach) -> None:
    """The way back retraces places the reach showed: its end's prediction stands, no loss."""
    core = TrackerCore()
    msgs = _feed(core, np.concatenate([reach, reach[::-1], np.repeat(reach[:1], 60, 0)]))
    assert not [e for e in _markers(msgs) if e[0] == "lost"] and core.demos.unseen == 0


def test_the_end_of_a_recording_played_is_no_loss_but_a_live_tracker_stopping_is(reach) -> None:
    played, live = TrackerCore(), TrackerCore()
    _feed(played, np.repeat(reach[:1], 60, 0))
    _feed(live, np.repeat(reach[:1], 60, 0))
    assert played.finish(recording_ended=True).messages == []  # the person stands as last seen, as after a replayer
    assert _markers(live.finish().messages) == [("lost", 0, AT_REST)]


def test_the_person_is_said_again_for_an_executor_that_appears_even_mid_reach(reach) -> None:
    """The person at rest was said once per track: an executor started anew (or one that saw the tracker go, and
    holds until a demonstration starts) held until the person's next reach."""
    core = TrackerCore()
    msgs = _feed(core, np.repeat(reach[:1], 60, 0))
    core.demos.say_again()
    msgs += _feed(core, np.repeat(reach[:1], 5, 0), t0=60 / RATE)
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST), ("start", 1, AT_REST), ("end", 1, AT_REST)]
    moving = next(i for i in range(30, len(reach)) if np.abs(reach[i] - reach[0]).max() > 0.2)
    t0 = 65 / RATE
    during = _feed(core, reach[30:moving + 10], t0=t0)  # a reach under way ...
    assert core.demos.reach.active
    core.demos.say_again()  # ... when the executor appears: said once the reach has ended and the body is still
    after = _feed(core, reach[moving + 10:], t0=t0 + (moving - 20) / RATE)
    events = _markers(during + after)
    assert events[:2] == [("start", 2, LIVE_CLASS), ("end", 2, LIVE_CLASS)] and events[2:] == [
        ("start", 3, AT_REST), ("end", 3, AT_REST)]
    executor = _executor_after(msgs + during + after)
    assert executor.stale_reason() == ""


def test_a_15_hz_sensor_s_person_at_rest_is_said_with_poses_on_the_library_s_clock(reach) -> None:
    """Its rate is known after a second, as the person at rest was said: its poses came at 15 a second, and the
    predictor reads their indices as time (30 a second). Now the rest waits for poses that all are on the clock."""
    core = TrackerCore()
    msgs = []
    for i, p in enumerate(MODEL.joint_positions(np.repeat(reach[:1], 45, 0))):  # 3 s at 15 Hz
        msgs += core.on_frame(i / 15.0, NAMES, p).messages
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST)]
    stamps = [m.stamp for m in msgs if isinstance(m, HumanPose)]
    assert len(stamps) >= 5 and np.allclose(np.diff(stamps), 1 / RATE)


@pytest.mark.parametrize(("rate", "noise", "seconds"), [(60.0, 0.02, 20.0), (30.0, 0.03, 10.0), (60.0, 0.03, 12.0)])
def test_a_person_standing_still_under_a_noisy_fast_sensor_is_never_lost(reach, rate: float, noise: float,
                                                                            seconds: float) -> None:
    """A review: a frame refused as a jump for its noise (a hand 'at 6.7 m/s' between two 60 Hz frames), and the next
    ones, near the track's body and the refused one alike, taken for another person after three: each new track was
    a 'lost' and a second's hold (60 Hz, 2 cm: 6 in 30 s, the robot held 21 s). At 60 Hz and 3 cm the frames that
    continued a refused one still lay near the track's body as a whole (2 losses in 30 s): another body is one
    elsewhere as a whole."""
    rng = np.random.default_rng(1)
    core = TrackerCore()
    msgs = []
    for i, p in enumerate(MODEL.joint_positions(np.repeat(reach[:1], int(seconds * rate), 0))):
        msgs += core.on_frame(i / rate, NAMES, p + rng.normal(0.0, noise, p.shape)).messages
    events = _markers(msgs)
    assert events[:2] == [("start", 0, AT_REST), ("end", 0, AT_REST)] and core.demos.rests == 1, events
    assert not [e for e in events if e[0] == "lost"] and core.demos.unseen == 0, core.refused


def test_a_walk_taken_for_a_reach_ended_by_its_time_limit_leaves_only_its_last_place(reach) -> None:
    """A review: a walk with the arm swinging is a 'reach' until max_reach_s ends it; its whole path was kept as the
    person's places, and walking on along it with the arm still was no loss (the robot went on, the person 0.6 m
    from its prediction). A reach ended by the time limit keeps only its last pose's places."""
    n = 330  # 11 s: pelvis out 0.8 m and back every 5.5 s, the arm swinging
    t = np.arange(n) / RATE
    walk = np.repeat(reach[:1], n, 0)
    walk[:, PELVIS_X] += 0.4 * (1 - np.cos(2 * np.pi * t / 5.5))
    walk[:, 7] += 0.5 * np.sin(2 * np.pi * t)  # r_shoulder_x
    on = np.repeat(walk[-1:], 30, 0)
    on[:, 7] = reach[0, 7]
    on[:, PELVIS_X] += np.linspace(0.0, 0.5, 30)  # then on along it, the arm still
    msgs = _feed(TrackerCore(), np.concatenate([np.repeat(reach[:1], 60, 0), walk, on]))
    events = _markers(msgs)
    assert ("end", 1, LIVE_CLASS) in events and events[events.index(("end", 1, LIVE_CLASS)) + 1] == (
        "lost", 1, LIVE_CLASS)


def test_a_body_that_moves_first_is_lost_and_its_reach_starts_as_it_would_have(reach) -> None:
    """Losing the person relearnt the hand's rest, and held back by a second each reach whose body moved first (the
    paper library's compound_0 #0 and #3 lean before the wrist leaves its rest: 39 frames after the onset, not 14
    and 9). The rest is the hand's in the body's frame: it stands, and the reach starts when it would have."""
    leaning = reach.copy()
    onset = next(i for i in range(30, len(reach)) if np.abs(reach[i] - reach[0]).max() > 0.02)
    leaning[onset:, PELVIS_X] += np.minimum(np.arange(len(reach) - onset) / 10, 1.0) * 0.15  # 15 cm in 1/3 s
    msgs = _feed(TrackerCore(), leaning)
    still = _feed(TrackerCore(TrackerConfig(moved_m=10.0)), leaning)  # never moved away
    starts = [[m.stamp for m in ms if isinstance(m, DemoMarker) and m.event == "start" and m.class_name == LIVE_CLASS]
              for ms in (msgs, still)]
    assert ("lost", 0, AT_REST) in _markers(msgs) and starts[0] == starts[1] and len(starts[0]) == 1


def test_a_person_turning_slowly_is_lost_at_about_25_deg_and_not_said_at_rest_until_they_stop(reach) -> None:
    """A review: turning in place at 10 deg/s, the person was said at rest one frame after the turn lost them, still
    turning: the body's points spread 1 cm rms over a second, under the 2 cm of a body at rest. The model's
    shoulders are 24 cm from its turning axis, so 10 cm is a turn of 2 asin(0.10 / 0.48) = 24 deg (docs: 33 deg)."""
    core = TrackerCore()
    turning = np.repeat(reach[:1], 180, 0)
    turning[:, PELVIS_YAW] += np.radians(10.0) * np.arange(1, 181) / RATE  # 10 deg/s for 6 s
    msgs = _feed(core, np.concatenate([np.repeat(reach[:1], 60, 0), turning, np.repeat(turning[-1:], 60, 0)]))
    assert _markers(msgs) == [("start", 0, AT_REST), ("end", 0, AT_REST), ("lost", 0, AT_REST),
                              ("start", 1, AT_REST), ("end", 1, AT_REST)]
    lost, again = (next(m for m in msgs if isinstance(m, DemoMarker) and m.event == e and m.demo_id == d)
                   for e, d in (("lost", 0), ("start", 1)))
    assert 23.0 <= (lost.stamp - 59 / RATE) * 10.0 <= 27.0  # degrees turned when lost (the smoothing lags one)
    assert again.stamp >= 240 / RATE - 1e-9  # said at rest once the turn has stopped, not while it goes on
