"""The tracker over Zenoh on loopback: keypoints in (Foresight's key, a recording, ROS 2), poses out; bad frames."""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest

from services.experiments.harness import ServiceThread
from services.ros2.core import KEYPOINTS_TYPE, Ros2Config, Ros2Mapping
from services.ros2.keypoints import keypoints_out
from services.ros2.node import Ros2Node
from services.tracker.__main__ import main as tracker_main
from services.tracker.config import PlaybackConfig, TrackerServiceConfig
from services.tracker.core import TrackerConfig
from services.tracker.demos import REST_POSES, reach_messages
from services.tracker.service import TrackerService
from shared.config import ConfigError, ZenohConfig
from shared.human import HumanModel
from shared.keypoints.library import write_keypoint_library
from shared.library import MotionLibrary
from shared.protocol import AT_REST, DemoMarker, HumanKeypoints, HumanPose, Keys, encode
from shared.rejects import RejectCounter
from shared.synthetic import generate_library
from shared.transport import Presence, TypedPublisher, open_session, subscribe_ordered

MODEL = HumanModel()
NAMES = list(MODEL.JOINT_NAMES)


class Collector:
    """Poses and markers in arrival order."""

    def __init__(self, session, keys: Keys) -> None:
        self.items: list = []
        self.cond = threading.Condition()
        self.sub = subscribe_ordered(session, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker}, self.add)

    def add(self, msg) -> None:
        with self.cond:
            self.items.append(msg)
            self.cond.notify_all()

    def wait(self, predicate, timeout: float = 20.0) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: predicate(self.items), timeout=timeout)

    def markers(self) -> list[DemoMarker]:
        with self.cond:
            return [m for m in self.items if isinstance(m, DemoMarker)]


def _reach_frames(rate_hz: float = 30.0) -> np.ndarray:
    """``(T, J, 3)`` joint positions of one synthetic reach, its first frame held 1.5 s before and after."""
    demo = generate_library(2, 1, seed=4).demos[0]
    joints = MODEL.joint_positions(demo.features)
    hold = int(1.5 * rate_hz)
    return np.concatenate([np.repeat(joints[:1], hold, 0), joints, np.repeat(joints[-1:], hold, 0)])


def _service(hub, session=None, keys: Keys | None = None, **kw) -> tuple[TrackerService, ServiceThread]:
    """A tracker in a thread; with ``session``, returns once its token (and so its subscription) is seen."""
    cfg = TrackerServiceConfig(**kw)
    service = TrackerService(cfg, hub())
    thread = ServiceThread("tracker", service.run).start()
    if session is not None:
        presence = Presence(session, keys, "tester")
        assert presence.wait_for(["tracker"], 20.0) == []
        presence.close()
        time.sleep(0.2)
    return service, thread


def _all_taken(service: TrackerService, n: int, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while service.stats.frames < n and time.monotonic() < end:
        time.sleep(0.05)
    return service.stats.frames >= n


def _sensor(session, keys: Keys) -> TypedPublisher[HumanKeypoints]:
    return TypedPublisher(session, keys.keypoints, block=True)


def _kp(frame: int, positions: np.ndarray, names=None, frame_id: str = "recorder") -> HumanKeypoints:
    return HumanKeypoints(stamp=time.time(), tick=-1, frame=frame, frame_id=frame_id, names=names or NAMES,
                          positions=positions)


def test_a_sensors_reach_becomes_poses_between_markers(zenoh_hub) -> None:
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    frames = _reach_frames()
    with open_session(tester) as session:
        service, thread = _service(hub, session, keys)
        try:
            got = Collector(session, keys)
            pub = _sensor(session, keys)
            for i, pos in enumerate(frames):
                pub.put(_kp(i, pos))
                time.sleep(1 / 30)
            assert got.wait(lambda items: any(isinstance(m, DemoMarker) and m.event == "end" for m in items))
            assert _all_taken(service, len(frames))
            items = list(got.items)
        finally:
            stats = thread.stop()
    # the person seen at rest (a demonstration of its own, once the rest is learnt), then the reach
    assert [(m.event, m.demo_id, m.true_class, m.class_name) for m in items if isinstance(m, DemoMarker)] == [
        ("start", 0, -1, AT_REST), ("end", 0, -1, AT_REST), ("start", 1, -1, "live"), ("end", 1, -1, "live")]
    rest = [m for m in items if isinstance(m, HumanPose) and m.demo_id == 0]
    assert 1 <= len(rest) <= REST_POSES and items[len(rest) + 1].n_samples == len(rest)
    items = reach_messages(items, set())
    poses = [m for m in items if isinstance(m, HumanPose)]
    assert isinstance(items[0], DemoMarker) and isinstance(items[-1], DemoMarker)
    assert [p.index for p in poses] == list(range(len(poses))) and items[-1].n_samples == len(poses)
    # the fitted poses put the wrist where the keypoints had it (smoothing lags a little)
    wrist = NAMES.index("r_wrist")
    fitted = np.stack([MODEL.joint_positions(p.features)[wrist] for p in poses])
    nearest = np.min(np.linalg.norm(fitted[:, None] - frames[None, :, wrist], axis=-1), axis=1)
    assert np.median(nearest) < 0.02
    assert stats.frames == len(frames) and stats.reaches == 1 and sum(stats.refused.values()) == 0


def _gone_quiet(hub, frames: np.ndarray) -> tuple[Collector, list[HumanKeypoints]]:
    """A tracker sent ``frames`` at 30 Hz, then nothing: what it published (once its ``lost`` came), what was sent."""
    tester = hub()
    keys = Keys(tester.prefix)
    with open_session(tester) as session:
        service, thread = _service(hub, session, keys)
        try:
            got = Collector(session, keys)
            pub = _sensor(session, keys)
            sent = []
            for i, pos in enumerate(frames):
                sent.append(_kp(i, pos))
                pub.put(sent[-1])
                time.sleep(1 / 30)
            assert got.wait(lambda items: any(isinstance(m, DemoMarker) and m.event == "lost" for m in items),
                            timeout=10.0)  # no further frame came: the silence lost it
            assert thread.thread.is_alive()  # the tracker goes on, ready for the next person
        finally:
            thread.stop()
    return got, sent


def test_a_sensor_gone_quiet_mid_reach_loses_the_reach_at_once(zenoh_hub) -> None:
    frames = _reach_frames()
    half = 45 + (len(frames) - 90) // 2  # the hold, then half of the reach: then the sensor stops
    got, sent = _gone_quiet(zenoh_hub, frames[:half])
    end = got.markers()[-1]
    assert [m.event for m in got.markers()][-2:] == ["start", "lost"]  # not at rest: no 'end'
    assert end.stamp == sent[-1].stamp
    assert end.n_samples == sum(isinstance(m, HumanPose) and m.demo_id == end.demo_id for m in got.items)


def test_a_sensor_gone_quiet_after_the_person_was_seen_at_rest_loses_them_on_the_wire(zenoh_hub) -> None:
    """The person at rest said, then the sensor quiet (the person out of view): nothing was published, and the
    executor went on around the rest's prediction, nobody watching. Now a `lost` of that demonstration, after its
    end (which the receivers' order rule refused before)."""
    got, sent = _gone_quiet(zenoh_hub, np.repeat(_reach_frames()[:1], 60, 0))  # 2 s at rest
    assert [(m.event, m.demo_id, m.class_name) for m in got.markers()] == [
        ("start", 0, AT_REST), ("end", 0, AT_REST), ("lost", 0, AT_REST)]
    assert got.markers()[-1].stamp == sent[-1].stamp  # at the last frame seen


def test_an_executor_that_appears_gets_the_person_at_rest_said_again(zenoh_hub) -> None:
    """Once per track: an executor started (or reconnected) after the person was said at rest held until their next
    reach. The executor's liveliness token appearing has the tracker say the person again."""
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    still = _reach_frames()[0]
    with open_session(tester) as session:
        service, thread = _service(hub, session, keys)
        token = None
        try:
            got = Collector(session, keys)
            pub = _sensor(session, keys)
            i = 0

            def rests() -> int:
                return sum(m.event == "end" and m.class_name == AT_REST for m in got.markers())

            while rests() < 1 and i < 150:
                pub.put(_kp(i, still))
                i += 1
                time.sleep(1 / 30)
            token = session.liveliness().declare_token(keys.alive("executor"))  # an executor appears
            for _ in range(60):
                pub.put(_kp(i, still))
                i += 1
                time.sleep(1 / 30)
            assert got.wait(lambda items: rests() >= 2, timeout=10.0), got.markers()
        finally:
            if token is not None:
                token.undeclare()
            thread.stop()
    assert [(m.event, m.demo_id) for m in got.markers()][:4] == [("start", 0), ("end", 0), ("start", 1), ("end", 1)]


def test_bad_frames_get_one_line_each_are_never_published_and_the_tracker_goes_on(zenoh_hub, caplog) -> None:
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    frames = _reach_frames()
    good = frames[0]
    caplog.set_level(logging.INFO)
    with open_session(tester) as session:
        service, thread = _service(hub, session, keys)
        try:
            got = Collector(session, keys)
            pub = _sensor(session, keys)
            raw = session.declare_publisher(keys.keypoints)
            no_wrist = good.copy()
            no_wrist[NAMES.index("r_wrist")] = np.nan
            far = good.copy()
            far[NAMES.index("r_hand")] = [1500.0, 0.0, 1.0]
            pub.put(_kp(0, no_wrist))                                          # a required point missing
            pub.put(_kp(1, good, names=[*NAMES[:-1], "left_pinky"]))          # a name the layout does not have
            pub.put(_kp(2, good, frame_id="camera_link"))                      # another coordinate frame
            for payload in (_wire(_kp(3, far)),                                # kilometres away
                            _wire(_kp(4, good), names=NAMES[:5]),              # a frame of another size
                            _wire(_kp(5, good), nan_x=True),                   # NaN in one coordinate
                            b"\x93\x01\x02"):                                   # not a message
                raw.put(payload)
            time.sleep(0.5)
            for i, pos in enumerate(frames):                                   # then a good reach
                pub.put(_kp(10 + i, pos))
                time.sleep(1 / 30)
            assert got.wait(lambda items: any(isinstance(m, DemoMarker) and m.event == "end" for m in items))
            raw.undeclare()
        finally:
            stats = thread.stop()
    assert thread.error is None
    assert stats.refused["missing"] == 1 and stats.refused["names"] == 1 and stats.refused["frame"] == 1
    text = caplog.text
    assert "frame 0 refused (missing: required point(s) missing: r_wrist)" in text
    assert "'left_pinky', not points of the layout foresight" in text
    assert "frame 2 refused (frame: frame 2 is in 'camera_link', the tracker takes 'recorder')" in text
    assert "'r_hand' at [1500.0, 0.0, 1.0] m, beyond 20 m" in text
    rejected = service.rejects.summary()
    assert "out-of-range 1" in rejected and "invariant" in rejected and "malformed" in rejected
    assert stats.reaches == 1  # the good reach went through: nothing of the bad frames was published


def _wire(msg: HumanKeypoints, names=None, nan_x: bool = False) -> bytes:
    """``msg``'s payload, altered after encoding (a sender that does not check what it sends)."""
    d = msgpack.unpackb(encode(msg), raw=False)
    if names is not None:
        d["names"] = names
    if nan_x:
        pos = msg.positions.copy()
        pos[0, 0] = np.nan
        d["positions"]["data"] = pos.astype("<f8").tobytes()
    return msgpack.packb(d, use_bin_type=True)


def test_from_file_plays_a_recording_through_the_wire(zenoh_hub, tmp_path: Path) -> None:
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    lib = generate_library(2, 2, seed=4)
    write_keypoint_library(MotionLibrary(lib.class_names, lib.demos[:2], [], "test"), tmp_path / "kp")
    recording = tmp_path / "kp" / f"{lib.demos[0].class_name}.csv"
    play = PlaybackConfig(rate_hz=30.0, lead_s=1.2, hold_s=1.2, gap_s=0.6)
    with open_session(tester) as session:
        got = Collector(session, keys)
        time.sleep(0.3)
        service, thread = _service(hub, from_file=recording, playback=play)
        stats = thread.join(60.0)  # ends on its own after the recording
        assert got.wait(lambda items: sum(isinstance(m, DemoMarker) and m.event == "end" for m in items) >= 1)
    n = sum(d.n_samples for d in lib.demos[:2] if d.class_name == lib.demos[0].class_name)
    assert stats.played >= n and stats.frames == stats.played  # every played frame came back through Zenoh
    starts = [m for m in got.markers() if m.event == "start" and m.class_name == "live"]
    assert len(starts) == stats.reaches >= 1


def test_ros2_pose_array_input(zenoh_hub) -> None:
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    mapping = Ros2Mapping(Ros2Config())
    frames = _reach_frames()
    with open_session(tester) as session:
        service, thread = _service(hub, session, keys, input="ros2", ros2_topic="/body/keypoints")
        try:
            got = Collector(session, keys)
            node = Ros2Node(session, 0, "/", "skeleton_driver", mapping.hashes, RejectCounter("driver"))
            pub = node.publisher("/body/keypoints", KEYPOINTS_TYPE)
            time.sleep(0.3)
            pub.put(keypoints_out(mapping, frames[0][:5], time.time(), "recorder"))  # 5 poses: not the point order
            for pos in frames:
                pub.put(keypoints_out(mapping, pos, time.time(), "recorder"))
                time.sleep(1 / 30)
            assert got.wait(lambda items: any(isinstance(m, DemoMarker) and m.event == "end" for m in items))
            assert _all_taken(service, len(frames))
            node.close()
        finally:
            stats = thread.stop()
    assert stats.reaches == 1 and stats.frames == len(frames)
    assert service.rejects.counts == {"/body/keypoints": 1}


def test_a_pose_array_of_another_count_is_refused_naming_the_order_expected_and_how_to_set_it() -> None:
    """A driver sending another count than the order taken (a MediaPipe one, 33 landmarks, to the layout coco17): every
    sample was refused on its count, the line naming neither the order taken nor how to give the driver's."""
    cfg = TrackerServiceConfig(input="ros2", tracker=dataclasses.replace(TrackerConfig(), layout="coco17"))
    service = TrackerService(cfg, ZenohConfig())
    mapping = Ros2Mapping(Ros2Config())
    names = service.core.layout.native_order
    with pytest.raises(ValueError) as info:
        service._on_pose_array(mapping, names, keypoints_out(mapping, np.zeros((33, 3)), time.time(), "recorder"))
    text = str(info.value)
    assert text.startswith(f"PoseArray: 33 poses, the tracker's point order has {len(names)} ([tracker] ros2_points): ")
    assert (f"pose i is --ros2-points[i], now {','.join(names[:5])},... ({len(names)}); set it to the driver's names "
            "in its pose order") in text
    assert len(text) <= 300  # what the reject counter's line shows of it
    service._on_pose_array(mapping, names, keypoints_out(mapping, np.zeros((len(names), 3)), time.time(), "recorder"))
    assert len(service.backlog) == 1  # the count of its order: taken
    short = ["pelvis", "r_shoulder", "l_shoulder", "r_elbow", "r_wrist"]  # an order given: said whole when short
    with pytest.raises(ValueError, match=r"now pelvis,r_shoulder,l_shoulder,r_elbow,r_wrist; set it"):
        service._on_pose_array(mapping, short, keypoints_out(mapping, np.zeros((17, 3)), time.time(), "recorder"))


def test_a_coco_driver_is_read_in_cocos_own_order_by_default(zenoh_hub) -> None:
    """The default order was the layout table's (12 names), which no driver publishes: a COCO driver's every sample
    (its 17 keypoints by id) was refused until its names were typed into --ros2-points."""
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    mapping = Ros2Mapping(Ros2Config())
    coco = ["nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder", "left_elbow",
            "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee",
            "left_ankle", "right_ankle"]  # COCO's keypoint ids 0..16
    made_of = {"left_hip": "pelvis", "right_hip": "pelvis", "left_ear": "head", "right_ear": "head",
               **{f"{s}_{p}": f"{s[0]}_{p}" for s in ("left", "right") for p in ("shoulder", "elbow", "wrist")}}
    frames = _reach_frames()
    sent = np.full((len(frames), len(coco), 3), np.nan)  # nose, eyes, legs: not seen
    for i, name in enumerate(coco):
        if name in made_of:
            sent[:, i] = frames[:, NAMES.index(made_of[name])]
    with open_session(tester) as session:
        service, thread = _service(hub, session, keys, input="ros2", ros2_topic="/body/keypoints",
                                   tracker=dataclasses.replace(TrackerConfig(), layout="coco17"))
        try:
            got = Collector(session, keys)
            node = Ros2Node(session, 0, "/", "coco_driver", mapping.hashes, RejectCounter("driver"))
            pub = node.publisher("/body/keypoints", KEYPOINTS_TYPE)
            time.sleep(0.3)
            for pos in sent:
                pub.put(keypoints_out(mapping, pos, time.time(), "recorder"))
                time.sleep(1 / 30)
            assert got.wait(lambda items: any(isinstance(m, DemoMarker) and m.event == "end" for m in items)), \
                service.rejects.summary()
            assert _all_taken(service, len(frames))
            node.close()
        finally:
            stats = thread.stop()
    assert stats.reaches == 1 and stats.frames == len(frames)  # the right wrist's reach, read off COCO's points
    assert service.rejects.total == 0 and not any(service.core.refused.values())


def test_cli_refuses_a_recording_that_is_not_one(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "reach.csv"
    bad.write_text("time,x,y\n0,1,2\n")
    with pytest.raises(SystemExit) as info:
        tracker_main(["--from", str(bad), "--connect", "tcp/127.0.0.1:9"], prog="foresight tracker")
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tracker.from_file" in err[0] and "header must be demo,frame" in err[0]
    for given in (["--from", str(tmp_path / "none.csv")], [f"--from={tmp_path / 'none.csv'}"],
                  ["--from-file", str(tmp_path / "none.csv")]):  # --from is the option's name, not only a prefix
        with pytest.raises(SystemExit):
            tracker_main(given, prog="foresight tracker")
        assert "is not a file" in capsys.readouterr().err


def test_a_recording_in_another_layout_is_refused_before_it_plays(tmp_path: Path, capsys) -> None:
    """It played, every frame was refused for its names, and the tracker exited 0 as if it had worked."""
    lib = generate_library(2, 1, seed=4)
    write_keypoint_library(MotionLibrary(lib.class_names, lib.demos[:1], [], "test"), tmp_path / "kp")
    recording = tmp_path / "kp" / f"{lib.demos[0].class_name}.csv"  # Foresight's own point names
    with pytest.raises(SystemExit) as info:
        tracker_main(["--from", str(recording), "--layout", "coco17", "--connect", "tcp/127.0.0.1:9"],
                     prog="foresight tracker")
    assert info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "tracker.from_file" in line and "does not fit the layout coco17" in line and "'pelvis'" in line


def test_config_checks() -> None:
    with pytest.raises(Exception, match="ros2_topic"):
        TrackerServiceConfig(ros2_topic="body").validate()
    for name in ("stop_with", "wait_for"):  # a typo was never seen: the tracker waited, or never stopped
        with pytest.raises(ConfigError, match=rf"^tracker.{name}: unknown service 'exector' \(did you mean "
                           r"'executor'\?\)$"):
            TrackerServiceConfig(**{name: ["exector"]}).validate()
    with pytest.raises(ConfigError, match=r"^tracker.ros2_points: \['rwrist'\] are not points of the layout"):
        TrackerServiceConfig(ros2_points=["pelvis", "rwrist"]).validate()  # every frame would be refused
    with pytest.raises(ConfigError, match=r"^tracker.ros2_points: they cannot form the required \['r_wrist'\]"):
        TrackerServiceConfig(ros2_points=["pelvis", "r_shoulder", "l_shoulder", "r_elbow"]).validate()  # the same
    TrackerServiceConfig(ros2_points=["pelvis", "r_shoulder", "l_shoulder", "r_elbow", "r_wrist"]).validate()
    with pytest.raises(ConfigError, match=r"^tracker.max_fit_hz: 3 fits a frame every 0.333 s at most, not within "
                       r"max_gap_s = 0.3 s: every frame would be a gap$"):  # 163 skipped, 17 refused, 0 poses
        TrackerServiceConfig(tracker=dataclasses.replace(TrackerConfig(), max_fit_hz=3.0)).validate()
    with pytest.raises(Exception, match="max_residual_m"):
        TrackerServiceConfig(tracker=dataclasses.replace(TrackerConfig(), max_residual_m=0.0)).validate()
    with pytest.raises(Exception, match="rate_hz"):
        TrackerServiceConfig(playback=PlaybackConfig(rate_hz=-1.0)).validate()


def test_refusals_are_counted_each_but_logged_once_a_second_per_reason(caplog) -> None:
    """A sensor with nobody in view refuses 30 frames a second: that was 30 warning lines a second."""
    service = TrackerService(TrackerServiceConfig(), ZenohConfig())
    caplog.set_level(logging.WARNING, logger="foresight.tracker")
    nobody = np.full((len(NAMES), 3), np.nan)
    for i in range(90):
        service.on_keypoints(_kp(i, nobody))
    service.on_keypoints(_kp(90, _reach_frames()[0], frame_id="camera_link"))  # another reason: its own line
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert service.core.refused["missing"] == 90 and len(lines) == 2, lines
    assert "frame 0 refused (missing" in lines[0] and "frame 90 refused (frame:" in lines[1]


def test_a_recordings_silence_loses_the_reach_before_its_next_frame(zenoh_hub, tmp_path: Path) -> None:
    """Frames missing from a recording are a silence like a live sensor's; playback did not check for it, so the
    reach stayed open until the next frame, seconds later."""
    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    frames = _reach_frames()
    half = len(frames) // 2
    recording = tmp_path / "gap.csv"
    with recording.open("w") as f:  # 2 s of frames dropped in the middle of the reach
        f.write(",".join(["demo", "frame", *(f"{p}_{a}" for p in NAMES for a in "xyz")]) + "\n")
        for i, pos in enumerate(frames):
            n = i if i < half else i + 60
            f.write(",".join(map(str, [0, n, *np.round(pos.reshape(-1), 5)])) + "\n")
    play = PlaybackConfig(rate_hz=30.0, lead_s=0.5, hold_s=0.5, gap_s=0.5)
    played_at_end: list[int] = []
    with open_session(tester) as session:
        got = Collector(session, keys)
        time.sleep(0.3)
        service, thread = _service(hub, from_file=recording, playback=play)
        add = got.add

        def note(msg) -> None:  # how far the playback was when the lost marker came
            if isinstance(msg, DemoMarker) and msg.event == "lost":
                played_at_end.append(service.stats.played)
            add(msg)
        got.add = note
        got.sub.undeclare()
        got.sub = subscribe_ordered(session, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker}, note)
        thread.join(60.0)
        assert got.wait(lambda items: any(isinstance(m, DemoMarker) and m.event == "lost" for m in items))
    lead = round(play.lead_s * play.rate_hz)
    assert played_at_end and played_at_end[0] <= lead + half  # it ended before a frame after the silence was played


def test_playback_stamps_each_frame_when_due_even_when_it_is_sent_late(zenoh_hub, tmp_path: Path, monkeypatch) -> None:
    """Frames sent late in a burst (a loaded machine) were stamped when sent: a few ms apart, they read as a jump
    of the body and were refused (seen once in CI)."""
    from shared.transport import subscribe

    hub = zenoh_hub
    tester = hub()
    keys = Keys(tester.prefix)
    frames = _reach_frames()[:40]
    recording = tmp_path / "late.csv"
    with recording.open("w") as f:
        f.write(",".join(["demo", "frame", *(f"{p}_{a}" for p in NAMES for a in "xyz")]) + "\n")
        for i, pos in enumerate(frames):
            f.write(",".join(map(str, [0, i, *np.round(pos.reshape(-1), 5)])) + "\n")
    calls = []

    def late(self, when: float, stop) -> bool:  # the first frame after a 0.5 s stall, the rest at once: all late
        if not calls:
            time.sleep(0.5)
        calls.append(when)
        return stop.is_set()

    monkeypatch.setattr(TrackerService, "_wait_until", late)
    sent: list[HumanKeypoints] = []
    with open_session(tester) as session:
        sub = subscribe(session, keys.keypoints, HumanKeypoints, sent.append)
        time.sleep(0.3)
        play = PlaybackConfig(rate_hz=30.0, lead_s=0.0, hold_s=0.0, gap_s=0.5)
        service, thread = _service(hub, from_file=recording, playback=play)
        stats = thread.join(60.0)
        sub.undeclare()
    assert stats is not None and len(sent) == stats.played >= 30
    gaps = np.diff([m.stamp for m in sorted(sent, key=lambda m: m.frame)])
    assert np.allclose(gaps, 1 / 30, atol=1e-6), gaps
    assert sum(stats.refused.values()) == 0, stats.refused


def test_a_recording_in_millimetres_is_refused_before_it_plays(tmp_path: Path, capsys) -> None:
    """It played, every frame was refused on receipt as beyond 20 m of the sensor, and the tracker exited 0."""
    lib = generate_library(2, 1, seed=4)
    write_keypoint_library(MotionLibrary(lib.class_names, lib.demos[:1], [], "test"), tmp_path / "kp")
    recording = tmp_path / "kp" / f"{lib.demos[0].class_name}.csv"
    rows = [r.split(",") for r in recording.read_text().splitlines()]
    mm = [rows[0]] + [r[:2] + [f"{float(c) * 1000:.3f}" if c else c for c in r[2:]] for r in rows[1:]]
    recording.write_text("\n".join(",".join(r) for r in mm) + "\n")
    with pytest.raises(SystemExit) as info:
        tracker_main(["--from", str(recording), "--connect", "tcp/127.0.0.1:9"], prog="foresight tracker")
    assert info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "tracker.from_file" in line and "demo 0: coordinates beyond 20 m" in line and "millimetres?" in line


@pytest.mark.parametrize("fault", ["on its side", "no wrist"])
def test_a_recording_on_its_side_or_without_a_required_point_is_refused_before_it_plays(tmp_path: Path, capsys,
                                                                                        fault: str) -> None:
    """Both played, every frame refused (upright; missing), exit 0, where library from-keypoints refused them."""
    lib = generate_library(2, 1, seed=4)
    write_keypoint_library(MotionLibrary(lib.class_names, lib.demos[:1], [], "test"), tmp_path / "kp")
    recording = tmp_path / "kp" / f"{lib.demos[0].class_name}.csv"
    rows = [r.split(",") for r in recording.read_text().splitlines()]
    for row in rows[1:]:
        if fault == "on its side":  # z forward, y down: a camera's frame
            for i in range(2, len(row), 3):
                row[i + 1], row[i + 2] = f"{-float(row[i + 2]):.5f}", row[i + 1]
        else:  # the wrist's column is there, never a value in it
            at = rows[0].index("r_wrist_x")
            row[at:at + 3] = ["", "", ""]
    recording.write_text("\n".join(",".join(r) for r in rows) + "\n")
    with pytest.raises(SystemExit) as info:
        tracker_main(["--from", str(recording), "--connect", "tcp/127.0.0.1:9"], prog="foresight tracker")
    assert info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "tracker.from_file" in line and f"{recording} demo 0: " in line
    assert ("leans" in line and "is z the keypoints' up?" in line if fault == "on its side" else
            "no frame with every required point" in line and "never given: r_wrist;" in line)


def test_a_backlog_standing_for_too_long_is_thinned_to_catch_up_and_said_once(caplog) -> None:
    """Zenoh's thread fitted every frame in turn: with a sensor faster than the fit the poses fell seconds behind
    the person (a review: 0.5 s at 60 Hz, 4.5 s at 240 Hz), and nothing was said."""
    service = TrackerService(TrackerServiceConfig(), ZenohConfig())
    caplog.set_level(logging.INFO, logger="foresight.tracker")
    still = _reach_frames()[0]
    t0 = time.time()
    batch = [(dataclasses.replace(_kp(i, still), stamp=t0 + i / 240), True) for i in range(240)]  # 1 s waiting
    service.work(batch)
    unfitted = service.core.unfitted
    assert service.stats.frames == 240 and service.stats.behind == unfitted  # every frame counted, most unfitted
    assert 240 - unfitted == 11  # every 24th (0.1 s: max_gap_s / 3) and the newest
    service.work([(dataclasses.replace(_kp(240 + i, still), stamp=t0 + 1 + i / 240), True) for i in range(3)])
    assert service.core.unfitted == unfitted  # a short batch is taken whole
    said = [r.getMessage() for r in caplog.records if "fell behind" in r.getMessage()]
    assert len(said) == 1 and "240 frames waiting" in said[0], said


def test_a_batch_that_fails_is_logged_and_the_worker_goes_on(caplog, monkeypatch) -> None:
    """A frame whose processing raised ended the worker thread: every later frame waited unfitted (a review)."""
    service = TrackerService(TrackerServiceConfig(), ZenohConfig())
    still, calls = _reach_frames()[0], []
    real = service.core.on_keypoints

    def first_fails(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("a bug")
        return real(*args, **kwargs)

    monkeypatch.setattr(service.core, "on_keypoints", first_fails)
    caplog.set_level(logging.ERROR, logger="foresight.tracker")
    stop = threading.Event()
    worker = threading.Thread(target=service._work, args=(stop,), daemon=True)
    worker.start()
    try:
        service.backlog.put((_kp(0, still), True))
        deadline = time.monotonic() + 5
        while not service.stats.failed and time.monotonic() < deadline:
            time.sleep(0.01)
        service.backlog.put((_kp(1, still), True))
        while service.core.accepted < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        stop.set()
        worker.join(5)
    assert service.stats.failed == 1 and service.core.accepted == 1
    assert f"fitting a batch of 1 frames on {service.keys.keypoints} failed unexpectedly" in caplog.text


def test_a_batch_failing_every_time_is_counted_each_time_with_one_traceback(caplog, monkeypatch) -> None:
    """Each failing batch logged its traceback: a bug on every frame of a 30 Hz sensor, 30 tracebacks a second."""
    service = TrackerService(TrackerServiceConfig(input="ros2", ros2_topic="/body/keypoints"), ZenohConfig())

    def fails(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(service.core, "on_keypoints", fails)
    still = _reach_frames()[0]
    with caplog.at_level(logging.WARNING):
        for i in range(100):
            service._work_safely([(_kp(i, still), False)])
    assert sum(1 for r in caplog.records if r.exc_info) == 1
    assert service.stats.failed == 100 and service.rejects.by_reason == {("/body/keypoints", "handler"): 100}


def test_frames_waiting_for_the_worker_are_no_silence() -> None:
    """check_silence ended the reach under way when the worker was late, though the frames that continue it were
    already queued (a review)."""
    cfg = TrackerServiceConfig(tracker=dataclasses.replace(TrackerConfig(), max_gap_s=0.05))
    service = TrackerService(cfg, ZenohConfig())
    frame = _reach_frames()[0]
    service.on_keypoints(_kp(0, frame))
    assert service.core.tracking
    service.backlog.put((_kp(1, frame), True))
    time.sleep(0.1)
    assert not service.check_silence() and service.core.tracking  # a frame waits: no silence
    service.backlog.take_all(0.0)
    assert service.check_silence() and not service.core.tracking  # nothing waits: the usual rule
