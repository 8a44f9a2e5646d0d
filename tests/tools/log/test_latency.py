"""Latencies from log times: pose -> occupancy -> plan, replanning period."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest

from shared.protocol import HumanPose, OccupancyGrid, Plan, encode
from tools.log.latency import Stat, format_latencies, run_latencies


@dataclass
class Msg:
    topic: str
    log_time: int
    data: bytes


def _plan(index: int) -> Plan:
    return Plan(stamp=0.0, tick=-1, step=0, goal_names=["a"], joint_names=["j"], dt=0.1, chosen=0, planning_ms=40.0,
                occupancy_tick=-1, occupancy_index=index, trajectories=np.zeros((1, 2, 1), np.float32),
                cost_smoothness=np.zeros(1), cost_obstacle=np.zeros(1), cost_human=np.zeros(1),
                cost_total=np.zeros(1), valid=np.ones(1, bool))


def test_latencies_from_log_times():
    ms = 1_000_000
    msgs = []
    for i in range(10):
        t = i * 33 * ms
        msgs.append(Msg("p", t, encode(HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=3, index=i,
                                                 features=np.zeros(12)))))
        occ = OccupancyGrid.from_dense(np.zeros((2, 2, 2)), np.zeros(3), 0.1, stamp=0.0, tick=-1, tick_last=True,
                                       demo_id=3, index=i, method="prediction")
        msgs.append(Msg("o", t + 4 * ms, encode(occ)))
    msgs += [Msg("x", 100 * ms, encode(_plan(2))), Msg("x", 300 * ms, encode(_plan(8)))]
    msgs.append(Msg("x", 301 * ms, b"\x00garbage"))  # ignored
    stats = run_latencies(msgs, {"pose": "p", "occupancy": "o", "plan": "x"})
    assert stats["pose_to_occupancy"] == Stat(10, 4.0, 4.0, 4.0)
    assert stats["pose_to_plan"].count == 2 and stats["pose_to_plan"].max == 300 - 8 * 33
    assert np.isclose(stats["pose_to_plan"].p50, ((100 - 66) + (300 - 264)) / 2)
    assert stats["occupancy_to_plan"].max == 300 - 264 - 4
    assert stats["replanning_period"] == Stat(1, 200.0, 200.0, 200.0)
    assert stats["planning"].p50 == 40.0
    assert "pose to occupancy" in format_latencies(stats)


def test_a_log_of_a_schema_version_this_build_does_not_read_is_said_so_not_zeros():
    """A review's `_v` 3 log: `log latency` printed a table of zero counts and exited 0."""
    import msgpack
    import pytest

    from shared.runtime import UserError

    def newer(data: bytes) -> bytes:
        return msgpack.packb({**msgpack.unpackb(data, raw=False), "_v": 3}, use_bin_type=True)

    msgs = [Msg("p", 0, newer(encode(HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=3, index=0,
                                                 features=np.zeros(12))))), Msg("x", 5, newer(encode(_plan(0))))]
    with pytest.raises(UserError, match=r"its 2 message\(s\) are of a schema version this build does not read "
                       r"\(HumanPose\._v: schema version '3', this build speaks 2"):
        run_latencies(msgs, {"pose": "p", "occupancy": "o", "plan": "x"})
    assert run_latencies([], {"pose": "p", "occupancy": "o", "plan": "x"})["planning"].count == 0  # empty: zeros


def test_empty_series_is_nan():
    s = Stat.of([])
    assert s.count == 0 and np.isnan(s.p50)


def test_plans_after_the_demonstration_ended_do_not_count_for_pose_to_plan():
    from shared.protocol import DemoMarker

    ms = 1_000_000
    pose = HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=1, index=0, features=np.zeros(12))
    end = DemoMarker(stamp=0.0, tick=-1, demo_id=1, event="end", true_class=0, class_name="a", n_samples=1)
    msgs = [Msg("p", 0, encode(pose)), Msg("x", 50 * ms, encode(_plan(0))), Msg("d", 60 * ms, encode(end)),
            Msg("x", 900 * ms, encode(_plan(0)))]
    stats = run_latencies(msgs, {"pose": "p", "occupancy": "o", "plan": "x", "demo": "d"})
    assert stats["pose_to_plan"] == Stat(1, 50.0, 50.0, 50.0)
    assert stats["replanning_period"].count == 1  # the period counts every plan


def test_with_the_tracker_keypoints_to_pose_and_to_plan_follow_the_frame_each_pose_came_from():
    from shared.protocol import HumanKeypoints

    ms = 1_000_000
    msgs = []
    for i in range(3):  # frames at 0, 33, 66 ms; each pose 7 ms after its frame (stamp = the frame's)
        stamp = 100.0 + i / 30
        msgs.append(Msg("k", i * 33 * ms, encode(HumanKeypoints(stamp=stamp, tick=-1, frame=i, frame_id="recorder",
                                                                names=["pelvis"], positions=np.zeros((1, 3))))))
        msgs.append(Msg("p", (i * 33 + 7) * ms, encode(HumanPose(stamp=stamp, tick=-1, tick_last=True, demo_id=0,
                                                                  index=i, features=np.zeros(12)))))
    bridged = HumanPose(stamp=100.5, tick=-1, tick_last=True, demo_id=0, index=3, features=np.zeros(12))
    msgs += [Msg("p", 120 * ms, encode(bridged)),  # interpolated across a gap: no frame of its own
             Msg("x", 150 * ms, encode(_plan(2)))]
    stats = run_latencies(msgs, {"pose": "p", "occupancy": "o", "plan": "x", "keypoints": "k"})
    assert stats["keypoints_to_pose"] == Stat(3, 7.0, 7.0, 7.0)
    assert stats["keypoints_to_plan"] == Stat(1, 150.0 - 66, 150.0 - 66, 150.0 - 66)
    assert "keypoints_to_pose" not in run_latencies(msgs, {"pose": "p", "occupancy": "o", "plan": "x"})


def test_the_slowest_plans_split_pose_to_plan_into_the_step_and_the_rest():
    """`--slowest`: a tail of slow steps reads apart from a tail of steps that started late."""
    from tools.log.latency import format_slowest, slowest_plans

    ms = 1_000_000
    msgs = []
    for i in range(4):
        t = (1000 + i * 100) * ms  # the run's first pose at 1 s of log time
        msgs.append(Msg("p", t, encode(HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=2, index=i,
                                                 features=np.zeros(12)))))
        occ = OccupancyGrid.from_dense(np.zeros((2, 2, 2)), np.zeros(3), 0.1, stamp=0.0, tick=-1, tick_last=True,
                                       demo_id=2, index=i, method="prediction")
        msgs.append(Msg("o", t + 5 * ms, encode(occ)))

    def plan(index: int, step: int, planning_ms: float) -> bytes:
        return encode(dataclasses.replace(_plan(index), step=step, planning_ms=planning_ms))

    # plan 1: a slow step (90 of its 95 ms); plan 2: a quick step that started late (10 of 85 ms); plan 3: on time
    msgs += [Msg("x", 1100 * ms, plan(0, 1, 90.0)), Msg("x", 1190 * ms, plan(1, 2, 10.0)),
             Msg("x", 1225 * ms, plan(2, 3, 20.0))]
    samples = []
    stats = run_latencies(msgs, {"pose": "p", "occupancy": "o", "plan": "x"}, samples)
    assert stats["pose_to_plan"].count == len(samples) == 3
    slow = slowest_plans(samples, 2)
    assert [s.step for s in slow] == [1, 2]
    assert np.isclose(slow[0].pose_to_plan_ms, 100.0) and np.isclose(slow[0].occupancy_to_plan_ms, 95.0)
    assert np.isclose(slow[0].not_planning_ms, 5.0) and np.isclose(slow[1].not_planning_ms, 75.0)
    assert np.isclose(slow[0].t_s, 0.1)  # seconds from the run's first pose
    assert slowest_plans(samples, 0) == [] and len(slowest_plans(samples, 10)) == 3
    table = format_slowest(slow).splitlines()
    assert len(table) == 4 and table[2].split()[:2] == ["1", "0.10"] and table[3].split()[-1] == "75.0"


def test_log_latency_slowest_on_a_written_log(run_log, capsys):
    import json

    from tools.log import cli

    assert cli.main(["latency", str(run_log), "--slowest", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [s["step"] for s in out["slowest"]] == [1]  # plan 0 was made from no occupancy (index -1)
    assert out["slowest"][0]["planning_ms"] == 12.0 and "not_planning_ms" in out["slowest"][0]
    assert cli.main(["latency", str(run_log), "--slowest", "3"]) == 0
    assert "slowest plans by pose -> plan" in capsys.readouterr().out
    assert cli.main(["latency", str(run_log)]) == 0 and "slowest" not in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_:
        cli.main(["latency", str(run_log), "--slowest", "-1"])
    assert exit_.value.code == 2
    assert "--slowest: must be 0 or more plans, got -1" in capsys.readouterr().err


@pytest.mark.parametrize("own_key_known", [True, False])
def test_a_stray_message_on_another_key_does_not_take_the_runs_place(tmp_path, own_key_known):
    """The channel of a schema was the last found: one HumanPose put on another key under the prefix (logged on a
    channel of its own) emptied every pose series, with status 0 and no word (a review)."""
    from itertools import count

    from shared.protocol import Keys
    from shared.recording.writer import McapLog
    from tools.log.latency import log_latencies

    keys, clock = Keys(), count(1_700_000_000_000_000_000, 1_000_000)  # 1 ms a message
    path = tmp_path / "run.mcap"
    log = McapLog(path, keys, None, clock=lambda: next(clock),
                  run_metadata={"prefix": keys.prefix} if own_key_known else {})
    for i in range(5):
        pose = HumanPose(stamp=0.1 * i, tick=i, tick_last=True, demo_id=3, index=i, features=np.zeros(12))
        log.on_sample(keys.pose, encode(pose))
        log.on_sample(keys.occupancy, encode(OccupancyGrid.from_dense(
            np.zeros((2, 2, 2)), np.zeros(3), 0.1, stamp=0.1 * i, tick=i, tick_last=True, demo_id=3, index=i,
            method="prediction")))
        log.on_sample(keys.plan, encode(_plan(i)))
        if i == 1:
            log.on_sample(f"{keys.prefix}/elsewhere/pose", encode(dataclasses.replace(pose, demo_id=7, index=0)))
    log.close()
    if own_key_known:  # the run's own key, from its metadata
        stats = log_latencies(path)
        assert stats["pose_to_plan"].count == 5 and stats["pose_to_occupancy"].count == 5
    else:  # which is the run's cannot be told: said, not guessed
        with pytest.raises(ValueError, match=rf"HumanPose on 2 keys \({keys.pose}, {keys.prefix}/elsewhere/pose|"
                           rf"HumanPose on 2 keys \({keys.prefix}/elsewhere/pose, {keys.pose}"):
            log_latencies(path)


def test_a_plan_that_comes_after_the_next_demonstration_s_first_poses_follows_its_occupancy_s_demonstration():
    """Pose -> plan was keyed by the newest pose's demonstration: a real-time plan of demonstration 1's occupancy
    that came after demonstration 2's first poses was timed from demonstration 2's pose of that index (10 ms, not 70)
    or, before that pose came, dropped."""
    from shared.protocol import DemoMarker

    ms = 1_000_000

    def pose(demo: int, index: int) -> bytes:
        return encode(HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=demo, index=index, features=np.zeros(12)))

    def marker(demo: int, event: str) -> bytes:
        return encode(DemoMarker(stamp=0.0, tick=-1, demo_id=demo, event=event, true_class=0, class_name="a",
                                 n_samples=6))

    occ = OccupancyGrid.from_dense(np.zeros((2, 2, 2), np.float32), np.zeros(3), 0.05, stamp=0.0, tick=-1,
                                   tick_last=True, demo_id=1, index=5, method="prediction")
    head = [Msg("p", 0, pose(1, 5)), Msg("o", 30 * ms, encode(occ)), Msg("d", 40 * ms, marker(1, "end")),
            Msg("d", 45 * ms, marker(2, "start")), Msg("p", 50 * ms, pose(2, 0))]
    topics = {"pose": "p", "occupancy": "o", "plan": "x", "demo": "d"}
    later_poses = [Msg("p", (50 + i) * ms, pose(2, i)) for i in range(1, 6)]
    for msgs in (head + later_poses, head):  # demonstration 2's pose of index 5 before the plan, and not yet
        stats = run_latencies(msgs + [Msg("x", 70 * ms, encode(_plan(5)))], topics)
        assert stats["pose_to_plan"] == Stat(1, 70.0, 70.0, 70.0)
        assert stats["occupancy_to_plan"] == Stat(1, 40.0, 40.0, 40.0)
