"""McapLog: every channel with its schema, the scene channels (decoded back with protobuf and the schemas the
file carries, not with the SDK that wrote them), rejects, and files that stay readable when the writer is
killed (SIGKILL)."""

from __future__ import annotations

import json
import signal
import textwrap
import threading
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from shared.foxglove.decode import read_scene, scene_stamps
from shared.foxglove.scene import SceneBuilder
from shared.protocol import ClockTick, Keys, encode
from shared.recording.reader import read_log
from shared.recording.writer import McapLog

from .conftest import SCENE, blob, sample_messages

REPO = Path(__file__).resolve().parents[3]
KEYS = Keys()


def test_every_channel_is_written_with_its_schema_and_decodes(tmp_path, pr2) -> None:
    from shared.human import HumanModel, place_in_scene

    path = tmp_path / "a.mcap"
    log = McapLog(path, KEYS, SceneBuilder(SCENE, pr2, HumanModel(), place_in_scene), scene_text="name = 'x'",
                  run_metadata={"mode": "lockstep"})
    msgs = sample_messages(pr2)
    for key, data in msgs:
        assert log.on_sample(key, data) is not None
    assert log.on_sample(KEYS.plan, msgs[0][1]) is None  # a HumanPose on the plan key: wrong schema
    assert log.on_sample(KEYS.occupancy, b"\xc1") is None
    log.close()
    log.close()  # idempotent
    assert log.viz_errors == 0 and log.viz_dropped == 0
    lf = read_log(path, keep=lambda ch: True)
    assert lf.complete
    topics = {c.topic: c for c in lf.channels.values()}
    for key, data in msgs:
        ch = topics[key]
        assert ch.message_encoding == "msgpack" and ch.schema_encoding == "jsonschema" and ch.count == 1
        assert lf.topic_messages(key)[0].data == data  # byte for byte
    assert topics["/foresight/rejected"].count == 2
    assert lf.metadata["foresight.rejects"] == {KEYS.plan: "1", KEYS.occupancy: "1"}
    assert lf.metadata["foresight.viz"] == {"dropped": "0", "unfinished": "0", "errors": "0"}
    # the scene channels: protobuf under the FileDescriptorSet each channel's schema holds, and the plots' JSON
    scene = {}
    for r in read_scene(path):
        scene.setdefault(r.topic, []).append(r.message)
    for topic, entity in {"/viz/scene": "obstacles", "/viz/robot": "robot/spheres", "/viz/plan": "plan/paths",
                          "/viz/human": "human/body"}.items():
        assert topics[topic].schema_name == "foxglove.SceneUpdate" and topics[topic].schema_encoding == "protobuf"
        assert scene[topic][0].entities[0].id == entity
    assert [e.id for e in scene["/viz/scene"][0].entities] == ["obstacles", *(f"cup/{c.name}" for c in SCENE.cups)]
    robot = scene["/viz/robot"][0].entities[0]
    assert len(robot.spheres) == len(pr2.sphere_radii)
    centers = pr2.sphere_centers(pr2.q_start).numpy().reshape(-1, 3)
    got = np.array([[s.pose.position.x, s.pose.position.y, s.pose.position.z] for s in robot.spheres])
    assert np.allclose(got, centers, atol=1e-6)
    assert robot.spheres[0].color.r == 1.0  # holding: orange
    paths = scene["/viz/plan"][0].entities[0].lines
    assert len(paths) == 2 and paths[1].thickness > paths[0].thickness  # chosen = 1 is highlighted
    cloud = scene["/viz/occupancy"][0]
    assert topics["/viz/occupancy"].schema_name == "foxglove.PointCloud"
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "probability", "red", "green", "blue", "alpha"]
    points = np.frombuffer(cloud.data, dtype=[("xyz", "<f4", (3,)), ("p", "<f4"), ("rgba", "u1", (4,))])
    grid = blob(0, 0, 0.0)
    kept = grid.values >= 0.05 * 255
    assert len(points) == int(np.count_nonzero(kept)) and cloud.point_stride == 20
    ijk = np.stack(np.unravel_index(grid.indices[kept].astype(np.int64), tuple(grid.dims)), axis=-1)
    assert np.allclose(points["xyz"], grid.origin + grid.resolution * (ijk + 0.5), atol=1e-6)
    assert np.allclose(points["p"], grid.values[kept] / 255.0, atol=1e-6)
    human = scene["/viz/human"][0].entities[0].lines
    assert len(human) == len(HumanModel().capsules(np.zeros(12))[1])
    assert {t.child_frame_id for tf in scene["/tf"] for t in tf.transforms} == {"robot_base", "end_effector"}
    costs = scene["/viz/costs"][0]
    jsonschema.validate(costs, json.loads(read_schema(path, "foresight.viz.Costs")))
    assert costs["chosen"] == "red_cup" and set(costs["total"]) == {"blue_cup", "red_cup"}


def read_schema(path: Path, name: str) -> bytes:
    """The data of schema ``name`` in an MCAP file."""
    from mcap.stream_reader import StreamReader

    return next(rec.data for rec in StreamReader(str(path)).records
                if type(rec).__name__ == "Schema" and rec.name == name)


def test_foxglove_channels_are_stamped_on_the_log_clock_not_the_simulated_one(tmp_path, pr2) -> None:
    """Lock-step messages carry simulated time (0 s, i.e. 1970); every Foxglove entity and transform,
    the static scene and world -> robot_base included, is stamped with the record's log time."""
    from shared.human import HumanModel, place_in_scene

    ticks = iter(range(10**6))
    clock = lambda: 1_700_000_000_000_000_000 + 1_000_000 * next(ticks)  # noqa: E731 - 1 ms per call
    path = tmp_path / "a.mcap"
    log = McapLog(path, KEYS, SceneBuilder(SCENE, pr2, HumanModel(), place_in_scene), clock=clock)
    for key, data in sample_messages(pr2):  # every stamp is 0.0
        assert log.on_sample(key, data) is not None
    log.close()
    stamps = scene_stamps(path)
    assert {(t, i) for t, i, *_ in stamps} == {
        ("/viz/scene", "obstacles"), *(("/viz/scene", f"cup/{c.name}") for c in SCENE.cups),
        ("/tf", "robot_base"), ("/tf", "end_effector"), ("/viz/robot", "robot/spheres"),
        ("/viz/occupancy", "points"), ("/viz/plan", "plan/paths"), ("/viz/human", "human/body"),
        ("/viz/costs", "chart")}
    for topic, ident, ns, log_time, publish_time in stamps:
        assert abs(ns - log_time) < 1000 and publish_time == log_time, (topic, ident, ns, log_time)


class _SlowOccupancy(SceneBuilder):
    """A scene builder whose occupancy update waits until the test releases it."""

    def __init__(self, robot) -> None:  # noqa: ANN001
        super().__init__(SCENE, robot)
        self.entered, self.release = threading.Event(), threading.Event()

    def occupancy_cloud(self, occ, stamp=None):  # noqa: ANN001, ANN201 - the SceneBuilder signature
        self.entered.set()
        self.release.wait(10)
        return super().occupancy_cloud(occ, stamp)


def test_foxglove_updates_never_hold_up_the_raw_log(tmp_path, pr2) -> None:
    """An occupancy's Foxglove update is built off the caller's thread: the caller logs the next message
    (a plan: the robot's input) while it is still being built, and a full queue drops updates, not messages."""
    builder = _SlowOccupancy(pr2)
    ticks = iter(range(10**6))
    clock = lambda: 1_700_000_000_000_000_000 + 1_000_000 * next(ticks)  # noqa: E731 - 1 ms per call
    path = tmp_path / "a.mcap"
    log = McapLog(path, KEYS, builder, clock=clock, viz_pending=1)
    msgs = dict(sample_messages(pr2))
    try:
        assert log.on_sample(KEYS.occupancy, msgs[KEYS.occupancy]) is not None
        assert builder.entered.wait(10)  # the update is being built ...
        for _ in range(3):  # ... while the caller goes on: each plan is logged, the first one's update waits,
            assert log.on_sample(KEYS.plan, msgs[KEYS.plan]) is not None  # the others find the queue full
        assert log.on_sample(KEYS.occupancy, encode(blob(1, 1, 1.0))) is not None  # due, dropped as well
        assert not builder.release.is_set() and log.viz_dropped == 3
    finally:
        builder.release.set()
    deadline = time.monotonic() + 10
    while log._viz.pending and time.monotonic() < deadline:  # the worker drains the queue
        time.sleep(0.01)
    # the dropped occupancy update did not count as drawn: the next one (0.05 s later) is drawn
    assert log.on_sample(KEYS.occupancy, encode(blob(2, 2, 1.05))) is not None
    log.close()
    lf = read_log(path, keep=lambda ch: True)
    occ_times = [m.log_time for m in lf.topic_messages(KEYS.occupancy)]
    assert len(lf.topic_messages(KEYS.plan)) == 3 and len(occ_times) == 3  # every message is in the raw log
    viz = lf.topic_messages("/viz/occupancy")  # stamped with the receive times, built later
    assert [m.log_time for m in viz] == [occ_times[0], occ_times[2]]
    assert len(lf.topic_messages("/viz/plan")) == 1
    assert lf.metadata["foresight.viz"] == {"dropped": "3", "unfinished": "0", "errors": "0"}


WRITER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from shared.foxglove.scene import SceneBuilder
    from shared.recording.writer import McapLog
    from shared.protocol import ClockTick, Keys, OccupancyGrid, encode
    from shared.scene import load_scene
    keys = Keys()
    scene = load_scene(None)
    log = McapLog(sys.argv[1], keys, SceneBuilder(scene), chunk_size=4096, flush_period_s=0.05, viz_thread=False)
    dense = np.zeros(scene.grid.dims, np.float32)
    dense[18:24, 12:20, 15:22] = 0.8
    n = 0
    while True:
        log.on_sample(keys.clock, encode(ClockTick(stamp=n * 0.2, tick=n, period=0.2)))
        if n % 50 == 0:  # a scene update (the occupancy's point cloud) every 50 ticks
            occ = OccupancyGrid.from_dense(dense, scene.grid.origin, scene.grid.resolution, stamp=n * 0.2, tick=n,
                                           tick_last=True, demo_id=0, index=n, method="prediction")
            log.on_sample(keys.occupancy, encode(occ))
        n += 1
        if n == 2000:
            log.flush()
            print("flushed", n, flush=True)
        time.sleep(0.0005 if n < 2000 else 0.01)
""")


def test_killed_writer_leaves_a_readable_file_scene_included(tmp_path, signalled) -> None:
    path = tmp_path / "killed.mcap"
    signalled(["-c", WRITER, str(path)], [(signal.SIGKILL, 0.3)], ready="flushed", timeout=10)
    lf = read_log(path, keep=lambda ch: True)
    assert not lf.complete
    msgs = lf.topic_messages(KEYS.clock)
    assert len(msgs) >= 2000
    from shared.protocol import decode

    ticks = [decode(m.data, ClockTick).tick for m in msgs]
    assert ticks == list(range(len(ticks)))  # nothing lost or garbled up to the last whole chunk
    scene = list(read_scene(path))  # the scene channels too, decoded with the schemas the file carries
    clouds = [r for r in scene if r.topic == "/viz/occupancy"]
    assert scene[0].topic == "/viz/scene" and len(clouds) >= 2000 // 50
    assert {len(r.message.data) for r in clouds} == {6 * 8 * 7 * 20}


def test_compressed_chunks_hold_the_same_messages(tmp_path, pr2) -> None:
    """zstd (default), lz4 and none: the same records read back; zstd and lz4 files are smaller."""
    sizes, contents = {}, {}
    for compression in ("none", "zstd", "lz4"):
        path = tmp_path / f"{compression}.mcap"
        stamps = iter(range(10**9, 2 * 10**9, 1000))
        log = McapLog(path, KEYS, None, compression=compression, clock=stamps.__next__)
        for _ in range(20):
            for key, payload in sample_messages(pr2):
                log.on_sample(key, payload)
        log.close()
        lf = read_log(path, keep=lambda ch: True)
        assert lf.complete
        sizes[compression] = path.stat().st_size
        contents[compression] = [(m.topic, m.log_time, m.data) for m in lf.messages]
    assert contents["zstd"] == contents["none"] == contents["lz4"] and len(contents["none"]) == 100
    assert sizes["zstd"] < sizes["none"] / 3 and sizes["lz4"] < sizes["none"]
    with pytest.raises(ValueError, match="compression must be one of zstd, lz4, none"):
        McapLog(tmp_path / "x.mcap", KEYS, None, compression="gzip")


def test_a_quiet_spell_holds_no_message_back_longer_than_the_flush_period(tmp_path, pr2) -> None:
    """Messages just before a quiet spell (an executor waiting for its peers) stayed in memory until the next
    message came, and a kill then lost them: the open chunk was flushed only when a message was logged."""
    path = tmp_path / "quiet.mcap"
    log = McapLog(path, KEYS, None, flush_period_s=0.2)
    try:
        sent = [log.on_sample(KEYS.clock, encode(ClockTick(stamp=0.1 * i, tick=i, period=0.1))) for i in range(3)]
        assert all(m is not None for m in sent)
        time.sleep(1.0)  # no message: the log's own timer flushes
        lf = read_log(path, keep=lambda ch: True)  # read as a killed run's file is
        assert not lf.complete and len(lf.topic_messages(KEYS.clock)) == 3
    finally:
        log.close()
    assert read_log(path).complete
    with pytest.raises(ValueError, match="flush period must be a finite number of seconds >= 0"):
        McapLog(tmp_path / "x.mcap", KEYS, None, flush_period_s=float("inf"))


def test_a_complete_log_s_scene_is_read_in_time_order_through_its_index(tmp_path, pr2) -> None:
    """read_scene held every scene message of a file before yielding the first (300 MB for a 17-minute run); a
    complete log is now read through its chunk index, in log-time order, the same records as a cut copy's."""
    from shared.human import HumanModel, place_in_scene

    ticks = iter(range(10**6))
    clock = lambda: 1_700_000_000_000_000_000 + 1_000_000 * next(ticks)  # noqa: E731 - 1 ms per call
    path = tmp_path / "a.mcap"
    log = McapLog(path, KEYS, SceneBuilder(SCENE, pr2, HumanModel(), place_in_scene), clock=clock,
                  chunk_size=4096)
    for _ in range(30):
        for key, data in sample_messages(pr2):
            log.on_sample(key, data)
    log.close()
    whole = [(r.topic, r.log_time) for r in read_scene(path)]
    assert whole == sorted(whole, key=lambda r: r[1]) and len(whole) > 30
    cut = tmp_path / "cut.mcap"  # no summary: read record by record, held and sorted
    data = path.read_bytes()
    cut.write_bytes(data[:data.rindex(b"\x0f")])  # into the summary: the footer and its offsets gone
    assert not read_log(cut).complete
    assert [(r.topic, r.log_time) for r in read_scene(cut)] == whole


def test_a_log_whose_summary_fails_its_crc_is_said_damaged_and_read_in_file_order(tmp_path, pr2) -> None:
    """The footer's summary CRC was not checked: one bit flipped in the last chunk index and `foresight log info`
    said "complete", `foresight log snapshot` drew an earlier moment as the last, without a word (a review)."""
    import struct

    from shared.recording.reader import summary_damage

    ticks = iter(range(10**6))
    path = tmp_path / "a.mcap"
    log = McapLog(path, KEYS, SceneBuilder(SCENE, pr2), chunk_size=4096,
                  clock=lambda: 1_700_000_000_000_000_000 + 1_000_000 * next(ticks))
    for _ in range(30):
        for key, data in sample_messages(pr2):
            log.on_sample(key, data)
    log.close()
    whole, intact = [(r.topic, r.log_time) for r in read_scene(path)], read_log(path)
    assert summary_damage(path) == "" and intact.complete and intact.state == "complete"
    data = bytearray(path.read_bytes())
    at, end, last_index = struct.unpack_from("<Q", data, len(data) - 8 - 20)[0], len(data) - 8 - 29, None
    while at < end:  # the summary's records: opcode, length, body
        if data[at] == 0x08:  # a chunk index: message start and end times, then the chunk's start offset
            last_index = at
        at += 9 + struct.unpack_from("<Q", data, at + 1)[0]
    data[last_index + 9 + 16] ^= 0x10
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    lf = read_log(damaged)
    assert not lf.complete and lf.summary_damaged and lf.state.startswith("DAMAGED (the summary, its index, fails its")
    assert lf.message_count == intact.message_count  # every message is there: only the index is not to be followed
    assert [(r.topic, r.log_time) for r in read_scene(damaged)] == whole


def test_a_complete_log_without_scene_channels_has_no_scene_records(tmp_path, pr2) -> None:
    """Read through its index, a log of raw messages only (an executor without the scene) gives no scene record."""
    path = tmp_path / "raw.mcap"
    log = McapLog(path, KEYS, None)
    for key, data in sample_messages(pr2):
        log.on_sample(key, data)
    log.close()
    assert read_log(path).complete and list(read_scene(path)) == []


def test_a_lock_step_log_has_its_scene_update_counts_too(tmp_path, pr2) -> None:
    """docs/executor.md lists foresight.viz as written on close; only the background thread's logs had it."""
    path = tmp_path / "lockstep.mcap"
    log = McapLog(path, KEYS, SceneBuilder(SCENE, pr2), viz_thread=False)
    for key, data in sample_messages(pr2):
        log.on_sample(key, data)
    log.close()
    assert read_log(path).metadata["foresight.viz"] == {"dropped": "0", "unfinished": "0", "errors": "0"}
    McapLog(tmp_path / "raw.mcap", KEYS, None).close()  # no scene channels: no counts of their updates
    assert "foresight.viz" not in read_log(tmp_path / "raw.mcap").metadata
