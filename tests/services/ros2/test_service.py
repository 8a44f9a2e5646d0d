"""The ROS 2 gateway on a real loopback session: what a ROS 2 node over rmw_zenoh would receive.

A "ROS side" session subscribes to the domain's keys and asks for the graph tokens, as rmw_zenoh
does; every sample must decode with rosbags by the type its key names, carry rmw_zenoh's attachment
with per-topic sequence numbers 1, 2, ..., and every topic must have its publisher token.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest
import zenoh
from rosbags.typesys import Stores, get_typestore

from services.ros2.core import TOPICS
from services.ros2.node import Ros2Node
from services.ros2.service import Ros2Service, Ros2ServiceConfig
from services.ros2.wire import Attachment
from shared.config import ZenohConfig
from shared.protocol import ClassPosterior, ClockTick, HumanPose, Keys, OccupancyGrid, Plan, RobotState
from shared.rejects import RejectCounter
from shared.transport import TypedPublisher, open_session

TS = get_typestore(Stores.ROS2_JAZZY)
JOINTS = ["torso_lift_joint", "r_shoulder_pan_joint"]


def _msgtype(dds: str) -> str:
    pkg, kind, _, name = dds.split("::")
    return f"{pkg}/{kind}/{name[:-1]}"


def test_every_sample_decodes_with_its_attachment_and_every_topic_has_a_token(
        zenoh_hub: Callable[[], ZenohConfig], wait_until: Callable[..., bool]) -> None:
    hub = zenoh_hub()
    keys = Keys(hub.prefix)
    got: list[tuple[str, bytes, bytes | None]] = []
    lock = threading.Lock()

    def on_ros(sample: zenoh.Sample) -> None:
        with lock:
            att = sample.attachment
            got.append((str(sample.key_expr), sample.payload.to_bytes(), att.to_bytes() if att is not None else None))

    stop = threading.Event()
    service = Ros2Service(Ros2ServiceConfig(viz_rate_hz=1000.0), zenoh_hub())
    with open_session(hub) as ros, open_session(zenoh_hub()) as foresight:
        sub = ros.declare_subscriber("0/**", on_ros)
        thread = threading.Thread(target=service.run, args=(stop,), daemon=True)
        thread.start()
        try:
            assert wait_until(lambda: len(list(ros.liveliness().get("@ros2_lv/0/**", timeout=1.0))) >= 8, 30.0)
            tokens = [str(r.ok.key_expr) for r in ros.liveliness().get("@ros2_lv/0/**", timeout=2.0) if r.ok]
            time.sleep(0.3)
            traj = np.zeros((2, 4, 2), np.float32)
            plan = Plan(stamp=1.0, tick=0, step=0, goal_names=["blue_cup", "red_cup"], joint_names=JOINTS, dt=0.1,
                        chosen=0, planning_ms=1.0, occupancy_tick=-1, occupancy_index=-1, trajectories=traj,
                        cost_smoothness=np.zeros(2), cost_obstacle=np.zeros(2), cost_human=np.zeros(2),
                        cost_total=np.ones(2), valid=np.ones(2, bool))
            TypedPublisher(foresight, keys.clock).put(ClockTick(stamp=0.0, tick=0, period=0.5))  # lock-step: /clock
            time.sleep(0.1)
            TypedPublisher(foresight, keys.plan).put(plan)
            state_pub = TypedPublisher(foresight, keys.robot_state)
            for i in range(3):
                state_pub.put(RobotState(stamp=1.0 + i, tick=i, joint_names=JOINTS, goal=0, reached=False,
                                         holding=False, reason="", q=np.full(2, 0.1 * i), qd=np.zeros(2)))
            dense = np.zeros((8, 8, 8))
            dense[2, 3, 4] = 0.9
            TypedPublisher(foresight, keys.occupancy).put(OccupancyGrid.from_dense(
                dense, np.zeros(3), 0.05, stamp=1.0, tick=0, tick_last=True, demo_id=0, index=0, method="prediction"))
            TypedPublisher(foresight, keys.posterior).put(ClassPosterior(
                stamp=1.0, tick=0, demo_id=0, index=0, class_names=["a", "b"], posterior=np.array([0.4, 0.6]),
                log_likelihood=np.zeros(2)))
            TypedPublisher(foresight, keys.pose).put(HumanPose(
                stamp=1.0, tick=0, tick_last=True, demo_id=0, index=0,
                features=np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])))
            expected = {service.mapping.key(role) for role in TOPICS}
            # every topic, not a count: the /clock samples (a tick and the states) made 11 before the human's marker
            # came, the gateway was stopped as it sent it, and the set missed its topic (a CI run)
            assert wait_until(lambda: expected <= {k for k, _, _ in list(got)}, 20.0), got
        finally:
            stop.set()
            thread.join(10.0)
            sub.undeclare()
    by_key: dict[str, list[tuple[bytes, Attachment]]] = {}
    for key, payload, att in got:
        by_key.setdefault(key, []).append((payload, Attachment.decode(att)))
    assert set(by_key) == expected
    for key, samples in by_key.items():
        msgtype = _msgtype(key.split("/")[-2])
        assert key.split("/")[-1] == TS.hash_rihs01(msgtype)
        for payload, _ in samples:
            TS.deserialize_cdr(payload, msgtype)  # decodes, by an independent type store
        assert [a.sequence_number for _, a in samples] == list(range(1, len(samples) + 1))
        assert len({a.gid for _, a in samples}) == 1 and samples[0][1].source_timestamp_ns > 1.7e18
    assert len(by_key[service.mapping.key("joint_states")]) == 3
    assert sum("/NN/" in t and t.endswith("/foresight") for t in tokens) == 1
    publishers = [t for t in tokens if "/MP/" in t]
    for role, topic in TOPICS.items():
        mangled = service.config.topic(role).replace("/", "%")
        assert sum(f"/{mangled}/" in t and t.split("/")[-2] == TS.hash_rihs01(topic.msgtype) for t in publishers) == 1


def test_the_human_is_placed_from_its_demonstrations_first_pose_when_demo_ids_restart(zenoh_hub, monkeypatch) -> None:
    features = np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])

    def pose(index: int, shift: float) -> HumanPose:
        f = features.copy()
        f[:2] += shift  # the pelvis elsewhere: the placement reference matters
        return HumanPose(stamp=1.0 + index, tick=-1, tick_last=True, demo_id=0, index=index, features=f)

    def published(poses: list[HumanPose]) -> list[bytes]:
        service, out = Ros2Service(Ros2ServiceConfig(), zenoh_hub()), []
        monkeypatch.setattr(service, "_viz", lambda _role, make: out.append(make()))
        for p in poses:
            service.on_human(p)
        return out

    long_running = published([pose(0, 0.0), pose(1, 0.0), pose(0, 0.3), pose(1, 0.35)])  # a new run: ids restart
    fresh = published([pose(0, 0.3), pose(1, 0.35)])
    assert long_running[-1] == fresh[-1]  # placed from the new run's first pose, not the old run's


def test_the_newest_marker_held_back_by_the_rate_limit_is_sent_when_its_window_passes() -> None:
    """The rate limit used to drop what came within a window for good: RViz kept an older occupancy on show."""
    from shared.config import ZenohConfig
    from shared.protocol import OccupancyGrid

    svc = Ros2Service(Ros2ServiceConfig(viz_rate_hz=1e-3), ZenohConfig())  # a window far longer than the test
    svc._pubs = {"occupancy": _Sent()}
    grids = []
    for i in range(3):
        dense = np.zeros((8, 8, 8))
        dense[i, 3, 4] = 0.9
        grids.append(OccupancyGrid.from_dense(dense, np.zeros(3), 0.05, stamp=1.0 + 0.05 * i, tick=-1,
                                              tick_last=True, demo_id=0, index=i, method="prediction"))
        svc.on_occupancy(grids[-1])
    pub = svc._pubs["occupancy"]
    assert pub.payloads == [svc.mapping.occupancy(grids[0])]  # the first at once; 1 and 2 inside its window
    svc.flush_viz()
    assert pub.sent == 1  # the window has not passed: still held
    svc.flush_viz(force=True)  # as at its window's end (or at shutdown): the newest, not the one between
    assert pub.payloads == [svc.mapping.occupancy(grids[0]), svc.mapping.occupancy(grids[2])]
    svc.flush_viz(force=True)
    assert pub.sent == 2  # sent once


def test_beside_a_robot_publishing_its_joint_states_the_gateway_echoes_none(
        zenoh_hub: Callable[[], ZenohConfig], wait_until: Callable[..., bool], caplog) -> None:
    """--robot ros2: the executor's RobotState is the robot's own reading; echoed onto /joint_states it came back to
    the executor as a second publisher's (116 refused in a review run, the others taken for measurements)."""
    hub = zenoh_hub()
    keys = Keys(hub.prefix)
    echoed: list[str] = []
    stop = threading.Event()
    service = Ros2Service(Ros2ServiceConfig(), zenoh_hub())
    with open_session(hub) as ros, open_session(zenoh_hub()) as foresight:
        driver = Ros2Node(ros, 0, "/", "robot_driver", service.mapping.hashes, RejectCounter("test"))
        driver.publisher("/joint_states", TOPICS["joint_states"].msgtype)  # the robot's driver, as simrobot
        sub = ros.declare_subscriber(service.mapping.key("joint_states"), lambda s: echoed.append(str(s.key_expr)))
        thread = threading.Thread(target=service.run, args=(stop,), daemon=True)
        with caplog.at_level("WARNING", logger="foresight.ros2"):
            thread.start()
            try:
                assert wait_until(lambda: service.robot_publishes is not None, 30.0)
                state_pub = TypedPublisher(foresight, keys.robot_state)
                for i in range(3):
                    state_pub.put(RobotState(stamp=1.0 + i, tick=i, joint_names=JOINTS, goal=0, reached=False,
                                             holding=False, reason="", q=np.full(2, 0.1 * i), qd=np.zeros(2)))
                time.sleep(1.0)
            finally:
                stop.set()
                thread.join(10.0)
                sub.undeclare()
                driver.close()
    assert service.robot_publishes == "/robot_driver" and echoed == []
    assert service.stats.sent["joint_states"] == 0
    assert "node /robot_driver publishes /joint_states (a robot's driver)" in caplog.text


def test_once_the_other_publisher_is_gone_the_gateway_publishes_the_joint_states_again() -> None:
    """A short-lived publisher (ros2 topic pub, a bag) silenced the gateway for the rest of its run."""
    from services.ros2.wire import endpoint_token

    service = Ros2Service(Ros2ServiceConfig(), ZenohConfig())
    token = endpoint_token(0, "other", 1, 2, "MP", "/", "topic_pub", "/joint_states", "sensor_msgs/msg/JointState",
                           "RIHS01_x", "q")
    service.on_graph(token)
    service.on_graph(endpoint_token(0, "other", 1, 3, "MS", "/", "topic_pub", "/joint_states",
                                    "sensor_msgs/msg/JointState", "RIHS01_x", "q"))  # a subscription: no matter
    assert service.robot_publishes == "/topic_pub"
    service.on_graph(token, alive=False)
    assert service.robot_publishes is None


class _Sent:
    """A publisher that keeps what it is given (the service's ``_put`` counts ``sent``)."""

    def __init__(self) -> None:
        self.payloads: list[bytes] = []
        self.sent = 0

    def put(self, payload: bytes) -> None:
        self.payloads.append(payload)
        self.sent += 1


def _state(t: float, tick: int = -1) -> RobotState:
    return RobotState(stamp=t, tick=tick, joint_names=JOINTS, goal=0, reached=False, holding=False, reason="",
                      q=np.zeros(2), qd=np.zeros(2))


def test_a_lock_step_run_publishes_its_simulated_time_on_clock(caplog) -> None:
    """A lock-step run's messages went out stamped from 0 (1970) with no /clock: RViz on the wall clock saw them 56
    years old, and a node with use_sim_time never saw time pass."""
    from services.ros2.wire import endpoint_token

    caplog.set_level(logging.INFO)
    service = Ros2Service(Ros2ServiceConfig(), ZenohConfig())
    clock = service._pubs["clock"] = _Sent()  # the node's publisher, as run() makes it
    times = lambda: [service.mapping.clock_in(p) for p in clock.payloads]  # noqa: E731
    service.on_state(_state(1.7e9))  # real time: no ticks, the stamps are the wall clock's, no /clock
    assert times() == []
    service.on_tick(ClockTick(stamp=0.0, tick=0, period=0.5))
    for i in range(1, 4):
        service.on_state(_state(0.02 * i, tick=0))
    service.on_state(_state(0.04, tick=0))  # a state again: the clock never goes back
    service.on_tick(ClockTick(stamp=0.5, tick=1, period=0.5))
    assert times() == pytest.approx([0.0, 0.02, 0.04, 0.06, 0.5])
    token = endpoint_token(0, "other", 1, 2, "MP", "/", "executor_robot", "/clock", "rosgraph_msgs/msg/Clock",
                           "RIHS01_x", "q")
    service.on_graph(token)  # the executor's ROS 2 robot link publishes the simulated time itself
    service.on_tick(ClockTick(stamp=1.0, tick=2, period=0.5))
    assert len(times()) == 5 and service.publishes("clock") == "/executor_robot"
    assert "node /executor_robot publishes /clock (a simulator" in caplog.text
    service.on_graph(token, alive=False)
    service.on_tick(ClockTick(stamp=0.0, tick=0, period=0.5))  # the next run: its time starts again
    assert times()[-1] == 0.0 and len(times()) == 6
    service.on_state(_state(1.7e9 + 5))  # a real-time run after it (a review: the wall clock went out on /clock)
    service.on_state(_state(1.7e9 + 6))
    assert len(times()) == 6
    off = Ros2Service(Ros2ServiceConfig(clock=False), ZenohConfig())
    off._pubs["clock"] = _Sent()
    off.on_tick(ClockTick(stamp=0.0, tick=0, period=0.5))
    assert off._pubs["clock"].sent == 0


def test_clock_samples_leave_in_the_order_their_times_were_taken() -> None:
    """A tick's thread took t = 1.0, a state's t = 1.1 while the first was still sending: 1.1 went out first, and
    the clock stepped back to 1.0 on the wire (the last note's left-alone item)."""
    service = Ros2Service(Ros2ServiceConfig(), ZenohConfig())
    sent: list[float] = []

    class _Slow(_Sent):
        def put(self, payload: bytes) -> None:
            t = service.mapping.clock_in(payload)
            if t == 1.0:
                time.sleep(0.3)  # the first sample's put takes a while (a congested link)
            sent.append(t)

    service._pubs["clock"] = _Slow()
    service.on_tick(ClockTick(stamp=0.0, tick=0, period=0.5))
    first = threading.Thread(target=service.on_tick, args=(ClockTick(stamp=1.0, tick=2, period=0.5),))
    first.start()
    time.sleep(0.1)
    service.on_state(_state(1.1, tick=2))
    first.join(timeout=10)
    assert sent == [0.0, 1.0, 1.1]


@pytest.mark.parametrize("names", [("foresight", "foresight"), ("foresight_a", "foresight_b")])
def test_of_two_gateways_one_publishes_the_clock(names: tuple[str, str], zenoh_hub: Callable[[], ZenohConfig],
                                                 wait_until: Callable[..., bool]) -> None:
    """Two gateways on one network (one per machine) each saw the other's /clock publisher, took it for a simulator
    and both stopped: a lock-step run's ROS 2 nodes saw no time at all. The one with the smaller session id
    publishes, whether they share a node name or not (named apart, both went quiet until 2026-11-29); real sessions
    on loopback, a ROS 2 subscriber counting what /clock carries."""
    hub = zenoh_hub()
    keys = Keys(hub.prefix)
    stop = threading.Event()
    gateways = [Ros2Service(Ros2ServiceConfig(node=name), zenoh_hub()) for name in names]
    clocks: list[bytes] = []
    with open_session(hub) as ros, open_session(zenoh_hub()) as foresight:
        sub = ros.declare_subscriber(gateways[0].mapping.key("clock"), lambda s: clocks.append(s.payload.to_bytes()))
        threads = [threading.Thread(target=g.run, args=(stop,), daemon=True) for g in gateways]
        for t in threads:
            t.start()
        try:  # each sees the other's publisher: the one with the larger session id defers
            assert wait_until(lambda: all(g._zid for g in gateways) and any(g.publishes("clock") for g in gateways),
                              30.0)
            time.sleep(0.5)
            tick_pub = TypedPublisher(foresight, keys.clock)
            for i in range(4):
                tick_pub.put(ClockTick(stamp=0.5 * i, tick=i, period=0.5))
            assert wait_until(lambda: len(clocks) >= 4, 20.0)
            time.sleep(0.5)
            first, second = sorted(gateways, key=lambda g: g._zid)  # while both run: stopped, their tokens go
            assert first.publishes("clock") is None and second.publishes("clock") is not None
        finally:
            stop.set()
            for t in threads:
                t.join(10.0)
            sub.undeclare()
    assert first.stats.sent["clock"] == 4 and second.stats.sent["clock"] == 0
    assert [gateways[0].mapping.clock_in(c) for c in clocks] == [0.0, 0.5, 1.0, 1.5]
