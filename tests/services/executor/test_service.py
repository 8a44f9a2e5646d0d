"""ExecutorService over Zenoh on loopback with fake predictor/planner: lock-step ticks, plan n-1 executed
during step n, determinism, safety hold and resume, bad input, MCAP contents."""

from __future__ import annotations

import errno
import logging
import os
import threading
import time

import msgpack
import numpy as np
import pytest

from services.executor.core import ExecutorConfig
from services.executor.result import ExecutorResult
from services.executor.service import ExecutorService
from shared.foxglove.decode import read_scene, scene_stamps
from shared.protocol import Keys, RobotState, decode
from shared.recording.reader import read_log
from shared.transport import Presence, open_session

from .conftest import SCENE, FakeSystem, new_hub


def lockstep_config(tmp_path, **kw) -> ExecutorConfig:
    base = dict(mode="lockstep", steps=8, step_period_s=0.2, state_rate_hz=25.0, lockstep_timeout_s=5.0,
                wait_for=["predictor", "planner"], mcap=str(tmp_path / "run.mcap"))
    base.update(kw)
    return ExecutorConfig(**base)


def run_lockstep(zenoh_hub, pr2, cfg: ExecutorConfig, **fake_kw):
    exec_z = zenoh_hub()
    fake = FakeSystem(zenoh_hub(), **fake_kw)
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    with fake.running():
        result = service.run()
    return result, fake, service


def test_lockstep_ticks_plans_and_goal(zenoh_hub, pr2, tmp_path) -> None:
    cfg = lockstep_config(tmp_path)
    result, fake, _ = run_lockstep(zenoh_hub, pr2, cfg)
    assert fake.ticks == list(range(8))  # ClockTick n for n = 0..7, in order
    assert result.steps == 8 and result.plans == 7  # plan of tick n runs during step n+1; the last never runs
    assert result.goal_per_step == [-1] + [0] * 7
    assert result.held_steps == 1  # step 0: no plan yet
    assert result.reached and 0 < result.reached_step < 8
    # states: one before tick 0 plus 5 per step, stamps on the simulated clock
    assert result.q.shape == (1 + 8 * 5, 8)
    assert np.allclose(result.times, np.r_[0.0, 0.04 * np.arange(1, 41)])
    # within limits and velocity limits all along
    lo, hi = pr2.lower.numpy(), pr2.upper.numpy()
    assert np.all(result.q >= lo - 1e-6) and np.all(result.q <= hi + 1e-6)
    v = np.abs(np.diff(result.q, axis=0)) / 0.04
    assert np.all(v <= pr2.velocity_limits.numpy() + 1e-4)
    # step 1 starts exactly where plan 0 starts (the executor published that state before tick 0)
    assert np.allclose(fake.plans[0].trajectories[0, 0], result.q[5], atol=1e-6)
    goal = fake.plans[-1].trajectories[0, -1]
    assert np.max(np.abs(result.q[-1] - goal)) <= cfg.goal_tolerance


def test_lockstep_mcap_has_one_time_base_for_foxglove(zenoh_hub, pr2, tmp_path) -> None:
    """The robot states and plans of a lock-step run carry simulated time (from 0 s); the Foxglove
    entities and transforms written for them, and the static scene, are all on the log's clock."""
    cfg = lockstep_config(tmp_path, steps=4)
    run_lockstep(zenoh_hub, pr2, cfg)
    lf = read_log(cfg.mcap, keep=lambda ch: True)
    keys = Keys()
    sim = [decode(m.data).stamp for m in lf.topic_messages(keys.robot_state) + lf.topic_messages(keys.plan)]
    assert sim and max(sim) <= 4 * 0.2 + 1e-9
    stamps = scene_stamps(cfg.mcap)
    kinds = {(topic, ident) for topic, ident, *_ in stamps}
    assert {("/tf", "robot_base"), ("/tf", "end_effector"), ("/viz/scene", "obstacles"),
            ("/viz/robot", "robot/spheres"), ("/viz/plan", "plan/paths"), ("/viz/occupancy", "points"),
            ("/viz/costs", "chart")} <= kinds
    first = min(m.log_time for m in lf.messages)
    last = max(m.log_time for m in lf.messages)
    for topic, ident, ns, log_time, publish_time in stamps:
        assert first <= log_time <= last and abs(ns - log_time) < 1000 and publish_time == log_time, (topic, ident)


def test_lockstep_is_deterministic(zenoh_hub, pr2, tmp_path) -> None:
    r1, _, _ = run_lockstep(new_hub(), pr2, lockstep_config(tmp_path, steps=6, mcap="none"), switch_at=3)
    r2, _, _ = run_lockstep(new_hub(), pr2, lockstep_config(tmp_path, steps=6, mcap="none"), switch_at=3)
    assert r1.goal_per_step == r2.goal_per_step == [-1, 0, 0, 0, 1, 1]
    assert np.array_equal(r1.q, r2.q)
    assert r1.mcap_path is None


def clear_stamps(msg) -> None:  # noqa: ANN001 - a protobuf message
    """Clear every ``timestamp`` field of a protobuf message, nested ones included."""
    for fd, value in msg.ListFields():
        if fd.name == "timestamp":
            msg.ClearField("timestamp")
        elif fd.message_type is not None:
            for item in ([value] if hasattr(value, "ListFields") else value):
                clear_stamps(item)


def test_lockstep_logs_are_reproducible_scene_included(zenoh_hub, pr2, tmp_path) -> None:
    """Two lock-step runs, the second also serving its scene live, log the same raw messages in the same order
    on every channel, and the same scene messages (every one decoded with the file's schema; only the
    receive-time stamps differ)."""
    from services.processes import free_port

    logs = []
    for run, live in (("a", 0), ("b", free_port())):
        cfg = lockstep_config(tmp_path / run, steps=5, live_port=live)
        run_lockstep(new_hub(), pr2, cfg, switch_at=3)
        raw = {}
        for m in read_log(cfg.mcap, keep=lambda ch: ch.message_encoding == "msgpack").messages:
            raw.setdefault(m.topic, []).append(m.data)
        scene = {}
        for r in read_scene(cfg.mcap):
            msg = r.message
            if isinstance(msg, dict):
                msg.pop("timestamp")
                text = repr(sorted(msg.items()))
            else:
                clear_stamps(msg)
                text = msg.SerializeToString(deterministic=True)
            scene.setdefault(r.topic, []).append(text)
        logs.append((raw, scene))
    (raw_a, scene_a), (raw_b, scene_b) = logs
    assert raw_a == raw_b and len(raw_a[Keys().plan]) == 5
    assert scene_a == scene_b and {"/viz/plan", "/viz/robot", "/viz/occupancy", "/viz/costs"} <= set(scene_a)


def test_lockstep_holds_without_plans_then_resumes(zenoh_hub, pr2, tmp_path) -> None:
    cfg = lockstep_config(tmp_path, steps=9, lockstep_timeout_s=0.3, mcap="none")
    result, fake, _ = run_lockstep(zenoh_hub, pr2, cfg, skip_plans=frozenset({2, 3, 4}), waypoints=40)
    # plan 1 runs in step 2, still in 3 (0.4 s old), too old from step 4 (0.6 s > 0.5 s) until plan 5 runs in 6
    q = result.q[1:].reshape(9, 5, 8)
    moved = np.abs(np.diff(np.concatenate([result.q[:1], q[:, -1]]), axis=0)).max(axis=1) > 1e-9
    assert moved.tolist() == [False, True, True, True, False, False, True, True, True]
    assert result.held_steps == 3


def run_sending(service: ExecutorService, fake: FakeSystem, payloads: list[tuple[str, bytes]],
                timeout: float = 30) -> None:
    """Run ``service`` against ``fake`` and, once its first tick is out, put ``payloads`` ((key, bytes) pairs).

    The plan of tick 0 waits until they are put (from the session that puts it): on a loaded machine a 4-step run
    could end before they arrived, and nothing was counted.
    """
    fake.first_plan.clear()
    with fake.running():
        t = threading.Thread(target=service.run, daemon=True)
        t.start()
        try:
            deadline = time.monotonic() + 20
            while not fake.ticks and time.monotonic() < deadline:
                time.sleep(0.01)
            for key, payload in payloads:  # while it runs
                fake.session.put(key, payload)
            fake.first_plan.set()
            t.join(timeout=timeout)
            ended = not t.is_alive()
        finally:  # a run that did not end (or a failure above) is stopped, never left behind the test
            if t.is_alive():
                service.stop.set()
                t.join(10)
    assert ended, f"the executor's run did not end within {timeout} s"


def test_mcap_has_every_channel_decodable_with_schemas(zenoh_hub, pr2, tmp_path) -> None:
    cfg = lockstep_config(tmp_path, steps=5)
    exec_z = zenoh_hub()
    fake = FakeSystem(zenoh_hub())
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    keys = Keys(exec_z.prefix)
    garbage = [b"", b"\x00\x01", msgpack.packb({"_type": "Plan", "_v": 1}), msgpack.packb([1, 2, 3])]
    run_sending(service, fake, [(key, g) for g in garbage for key in (keys.plan, keys.occupancy)])
    result = service.result
    assert result.steps == 5
    assert sum(result.rejects.values()) == 2 * len(garbage)
    lf = read_log(cfg.mcap, keep=lambda ch: True)
    assert lf.complete and not lf.error
    by_topic = {c.topic: c for c in lf.channels.values()}
    for key in (keys.plan, keys.occupancy, keys.robot_state, keys.clock):
        ch = by_topic[key]
        assert ch.message_encoding == "msgpack" and ch.schema_encoding == "jsonschema"
        assert ch.schema_name.startswith("foresight.") and ch.count > 0
        for m in lf.topic_messages(key):
            decode(m.data)
    assert by_topic[keys.clock].count == 5
    assert by_topic[keys.robot_state].count == 1 + 5 * 5
    assert by_topic[keys.plan].count == 5
    for topic in ("/viz/scene", "/viz/robot", "/viz/plan", "/viz/occupancy", "/tf"):
        assert by_topic[topic].message_encoding == "protobuf" and by_topic[topic].count > 0
    assert by_topic["/viz/costs"].message_encoding == "json" and by_topic["/viz/costs"].count == 5
    assert by_topic["/foresight/rejected"].count == 2 * len(garbage)
    assert lf.metadata["foresight.rejects"] == {keys.plan: "4", keys.occupancy: "4"}
    assert lf.metadata["foresight.run"]["mode"] == "lockstep"
    assert b"pr2_two_cups" in lf.attachments["scene.toml"]


def test_without_a_log_only_the_keys_it_uses_are_checked(zenoh_hub, pr2, tmp_path) -> None:
    """With no MCAP log the executor decodes plans, poses, markers and grids only; its consumers check the rest."""
    cfg = lockstep_config(tmp_path, steps=4, mcap="none")
    exec_z = zenoh_hub()
    fake = FakeSystem(zenoh_hub())
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    keys = Keys(exec_z.prefix)
    garbage = [b"", b"\x00\x01", msgpack.packb([1, 2, 3])]
    run_sending(service, fake, [(key, g) for g in garbage
                                for key in (keys.plan, keys.robot_state, keys.posterior, keys.clock)])
    assert service.result.steps == 4 and service.result.mcap_path is None
    assert service.result.rejects == {keys.plan: len(garbage)}


def test_realtime_run_starts_its_clock_once_the_wait_for_services_are_there(zenoh_hub, pr2) -> None:
    exec_z = zenoh_hub()
    cfg = ExecutorConfig(mode="realtime", steps=0, state_rate_hz=50.0, mcap="none", wait_for=["planner"])
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    states: list[RobotState] = []
    keys = Keys(exec_z.prefix)
    with open_session(zenoh_hub()) as watch:
        sub = watch.declare_subscriber(keys.robot_state,
                                       lambda s: states.append(decode(s.payload.to_bytes(), RobotState)))
        t = threading.Thread(target=service.run)
        t.start()
        try:
            time.sleep(1.5)
            assert not states  # no planner yet: the run has not started
            planner = Presence(watch, keys, "planner")
            deadline = time.monotonic() + 20
            while len(states) < 5 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert len(states) >= 5 and states[0].tick == -1
            planner.close()
        finally:
            service.stop.set()
            t.join(timeout=10)
            sub.undeclare()
    assert not t.is_alive()


def test_realtime_holds_when_predictor_stops_and_resumes(zenoh_hub, pr2, tmp_path, caplog) -> None:
    caplog.set_level(logging.INFO, logger="foresight.executor")
    exec_z = zenoh_hub()
    cfg = ExecutorConfig(mode="realtime", steps=0, state_rate_hz=50.0, stale_limit_s=0.3, mcap="none",
                         wait_for=["predictor", "planner"])
    fake = FakeSystem(zenoh_hub(), waypoints=200)
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    states: list[RobotState] = []
    with fake.running(realtime_hz=10.0), open_session(zenoh_hub()) as watch:
        sub = watch.declare_subscriber(Keys(exec_z.prefix).robot_state,
                                       lambda s: states.append(decode(s.payload.to_bytes(), RobotState)))
        t = threading.Thread(target=service.run)
        t.start()
        try:
            deadline = time.monotonic() + 10
            while not (states and not states[-1].holding) and time.monotonic() < deadline:
                time.sleep(0.05)
            assert states and not states[-1].holding, "never started moving"
            fake.predictor_on.clear()  # the predictor goes away
            time.sleep(1.0)
            held = states[-1]
            assert held.holding and held.reason.startswith("occupancy is"), held.reason
            q_held = held.q.copy()
            time.sleep(0.3)
            assert np.array_equal(states[-1].q, q_held) and np.all(states[-1].qd == 0)
            fake.predictor_on.set()  # ... and comes back
            time.sleep(1.0)
            assert not states[-1].holding
            assert np.abs(states[-1].q - q_held).max() > 1e-4
        finally:
            service.stop.set()
            t.join(timeout=10)
            sub.undeclare()
    assert not t.is_alive()
    assert service.result.held_steps > 0
    # each change is logged once, not on every 20 ms state (the quoted age changes every time)
    lines = [r.getMessage() for r in caplog.records if r.name == "foresight.executor"]
    assert sum(1 for m in lines if "holding at" in m and "occupancy is" in m) == 1, lines
    assert sum(1 for m in lines if "resuming at" in m) == 2, lines  # after the first plan, after the hold


@pytest.mark.parametrize("bad", [dict(start_q=[0.0] * 3), dict(start_q=[9.0] * 8)])
def test_bad_start_configuration_is_named(pr2, zenoh_hub, bad) -> None:
    from services.executor.core import ExecutorError

    with pytest.raises(ExecutorError, match="start_q"):
        ExecutorService(ExecutorConfig(**bad), zenoh_hub(), robot=pr2, human=(None, None), scene=SCENE)


def fuzz_payloads(rng: np.random.Generator, key: str, keys: Keys, n: int) -> list[bytes]:
    """Malformed payloads for ``key``: random bytes, truncated and corrupted valid messages, other types."""
    from shared.protocol import ClockTick, encode

    valid = encode(ClockTick(stamp=1.0, tick=3, period=0.2)) if key != keys.clock else \
        encode(RobotState(stamp=0.0, tick=0, joint_names=["a"], goal=0, reached=False, holding=False, reason="",
                          q=np.zeros(1), qd=np.zeros(1)))
    nan_state = msgpack.unpackb(encode(RobotState(stamp=0.0, tick=0, joint_names=["a"], goal=0, reached=False,
                                                  holding=False, reason="", q=np.zeros(1), qd=np.zeros(1))))
    nan_state["q"]["data"] = np.array([np.nan]).tobytes()
    out = []
    for i in range(n):
        kind = i % 4
        if kind == 0:
            out.append(rng.bytes(int(rng.integers(0, 200))))
        elif kind == 1:
            out.append(valid[: int(rng.integers(0, len(valid)))])  # truncated
        elif kind == 2:
            out.append(valid)  # a valid message of the wrong type for this key
        else:
            out.append(msgpack.packb(nan_state))  # NaN in an array (wrong type too, except on robot/state)
    return out


def test_fuzzed_input_on_every_key_is_rejected_and_the_run_completes(zenoh_hub, pr2, tmp_path) -> None:
    cfg = lockstep_config(tmp_path, steps=6)
    exec_z = zenoh_hub()
    fake = FakeSystem(zenoh_hub())
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    keys = Keys(exec_z.prefix)
    rng = np.random.default_rng(0)
    payloads = [(key, p) for key in keys.data_keys() for p in fuzz_payloads(rng, key, keys, 100)]
    sent = {key: sum(k == key for k, _ in payloads) for key in keys.data_keys()}
    run_sending(service, fake, payloads, timeout=60)
    assert service.result.steps == 6 and service.result.plans == 5
    assert service.result.rejects == sent
    lf = read_log(cfg.mcap)
    assert lf.complete
    assert {k: int(v) for k, v in lf.metadata["foresight.rejects"].items()} == sent
    assert {c.topic: c.count for c in lf.channels.values()}["/foresight/rejected"] == sum(sent.values())


def test_a_log_that_cannot_be_written_costs_the_robot_nothing(pr2, tmp_path, caplog) -> None:
    """A full disk under the MCAP: the plan still reaches the robot; the failures are counted and said."""
    from shared.config import ZenohConfig
    from shared.protocol import Plan, encode
    from shared.recording.writer import McapLog

    service = ExecutorService(ExecutorConfig(mcap=str(tmp_path / "run.mcap")), ZenohConfig(listen=[], connect=[]),
                              robot=pr2, human=(None, None), scene=SCENE)
    service.mcap = McapLog(str(tmp_path / "run.mcap"), service.keys, None, flush_period_s=0.0)

    def full_disk(*args, **kwargs) -> None:
        raise OSError(28, "No space left on device")

    service.mcap.log_message = full_disk
    service.mcap.reject = full_disk
    q0 = service.core.q.astype(np.float64)
    traj = np.stack([np.linspace(q0, q0 + 0.1, 15)] * 2).astype(np.float32)
    plan = Plan(stamp=0.0, tick=0, step=0, goal_names=["a", "b"], joint_names=list(service.limits.joint_names),
                dt=0.1, chosen=0, planning_ms=1.0, occupancy_tick=0, occupancy_index=0, trajectories=traj,
                cost_smoothness=np.ones(2), cost_obstacle=np.ones(2), cost_human=np.ones(2), cost_total=np.ones(2),
                valid=np.ones(2, bool))
    with caplog.at_level(logging.ERROR, logger="foresight.executor"):
        service._on_sample(service.keys.plan, encode(plan), "planner")  # as Zenoh's callback would
        service._on_sample(service.keys.plan, b"\x00garbage", "planner")  # refused: its record fails too
    assert service.inbox.latest().plan is not None  # the robot has its plan
    assert service.result.log_write_failures == 2
    assert ["writing the MCAP log failed (1 so far): OSError: [Errno 28] No space left on device"] == [
        r.getMessage().split("executor: ", 1)[1] for r in caplog.records if "MCAP log failed" in r.getMessage()]



def run_on_a_disk_full_after(size: int, pr2, tmp_path, monkeypatch) -> tuple[ExecutorConfig, ExecutorResult]:
    """A 10-step real-time run without peers whose MCAP's disk refuses every write once the file is ``size`` bytes."""
    import shared.recording.direct_file as direct_file
    from shared.config import ZenohConfig

    real_write = os.write

    def full(fd: int, data) -> int:
        if os.fstat(fd).st_size > size and os.readlink(f"/proc/self/fd/{fd}").endswith("run.mcap"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, data)

    monkeypatch.setattr(direct_file.os, "write", full)
    cfg = ExecutorConfig(mode="realtime", steps=10, wait_for=[], require_occupancy=False,
                         mcap=str(tmp_path / "run.mcap"), mcap_compression="none")
    service = ExecutorService(cfg, ZenohConfig(listen=["tcp/127.0.0.1:0"], connect=[], multicast_scouting=False),
                              robot=pr2, human=(None, None), scene=SCENE)
    return cfg, service.run()


def test_a_disk_that_stays_full_ends_the_log_but_never_the_run(pr2, tmp_path, monkeypatch) -> None:
    """The loop's own flushes (after each published state; lock-step's waits) and the close at the end went to
    the log unguarded: once a full disk had ended it, the next state raised and run() ended with an OSError."""
    import shared.recording.direct_file as direct_file

    monkeypatch.setattr(direct_file, "MAX_HELD_BYTES", 1024)
    cfg, result = run_on_a_disk_full_after(4096, pr2, tmp_path, monkeypatch)
    assert result.steps == 10 and result.log_write_failures > 0
    assert not read_log(cfg.mcap).complete  # ends where the disk stopped taking bytes

def test_the_human_source_ending_its_stream_is_not_reported_as_gone(pr2, caplog) -> None:
    """The replayer's normal end after its end marker was logged "replayer is gone: holding the robot"."""
    from shared.config import ZenohConfig

    service = ExecutorService(ExecutorConfig(mode="realtime"), ZenohConfig(), robot=pr2, human=(None, None),
                              scene=SCENE)
    caplog.set_level(logging.INFO, logger="foresight.executor")
    service._on_peer("replayer", True)
    service.core.note_demonstration("end", demo_id=0, n_samples=10)
    service._on_peer("replayer", False)
    assert "replayer" not in service.core.gone
    text = caplog.text
    assert "is gone" not in text and "replayer ended its stream after the demonstration's end" in text
    service._on_peer("planner", True)
    service._on_peer("planner", False)  # a fault: said so
    assert "planner is gone: holding the robot" in caplog.text and "planner" in service.core.gone
    service._on_peer("planner", True)
    assert "planner is back" in caplog.text


def test_the_default_log_name_of_a_run_started_in_the_same_second_is_its_own(tmp_path, monkeypatch) -> None:
    """Each claim takes a name no other has: the name was checked, then opened later, and two executors started
    within the same second both took it (the second refused by the first one's lock instead of taking -2)."""
    monkeypatch.chdir(tmp_path)
    config = ExecutorConfig()
    first, second = config.mcap_path("20261127T120000Z"), config.mcap_path("20261127T120000Z")
    assert (first.name, second.name) == ("20261127T120000Z.mcap", "20261127T120000Z-2.mcap")
    assert first.read_bytes() == second.read_bytes() == b""  # claimed: on the disk before either log is opened
    barrier = threading.Barrier(8)

    def claim(names: list) -> None:
        barrier.wait()
        names.append(config.mcap_path("20261127T120001Z").name)

    names: list[str] = []
    threads = [threading.Thread(target=claim, args=(names,)) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(names) == sorted(["20261127T120001Z.mcap"] + [f"20261127T120001Z-{n}.mcap" for n in range(2, 9)])


def test_a_service_gone_mid_lockstep_run_is_said_and_the_run_says_it_went_on_without_it(pr2, caplog) -> None:
    """Lock-step acts on no liveliness event, and said none: a compose run whose planner was killed went quiet for
    30 s a tick and ended with exit 0 as if nothing had happened (a review of docker compose run for real)."""
    from shared.config import ZenohConfig

    cfg = ExecutorConfig(mode="lockstep", steps=2, wait_for=[], lockstep_timeout_s=0.2, mcap="")
    service = ExecutorService(cfg, ZenohConfig(listen=["tcp/127.0.0.1:0"], connect=[], multicast_scouting=False),
                              robot=pr2, human=(None, None), scene=SCENE)
    caplog.set_level(logging.INFO, logger="foresight.executor")
    for name, alive in (("planner", True), ("replayer", False), ("view", False), ("planner", False),
                        ("planner", False), ("planner", True)):  # a view leaving: no tick waits for it
        service._on_peer(name, alive)
    gone = [r for r in caplog.records if "is gone" in r.getMessage()]
    assert len(gone) == 1 and gone[0].levelno == logging.WARNING and "planner is gone: each tick" in gone[0].message
    assert "planner is back" in caplog.text and not service.core.gone  # said, not acted on
    result = service.run()  # no planner at all: each tick waits 0.2 s and goes on
    assert result.lockstep_timeouts == 2
    assert "2 tick(s) went on without their plan or prediction" in caplog.text


def test_a_lockstep_run_that_went_on_without_its_inputs_exits_1(monkeypatch, capsys) -> None:
    """A compose run whose planner was killed ended 'done ... reached=True' with status 0: scripts took it for a run."""
    import services.executor.__main__ as executor_main
    from services.executor.result import ExecutorResult

    class Ran:
        def __init__(self, *_a) -> None:
            pass

        def run(self) -> ExecutorResult:
            return ExecutorResult(mcap_path="runs/x.mcap", lockstep_timeouts=self.timeouts)

    argv = ["--mode", "lockstep", "--steps", "1", "--connect", "tcp/127.0.0.1:9"]
    for timeouts, status in ((2, executor_main.INCOMPLETE), (0, 0)):
        Ran.timeouts = timeouts
        monkeypatch.setattr(executor_main, "ExecutorService", Ran)
        assert executor_main.main(argv) == status
        assert "mcap: runs/x.mcap" in capsys.readouterr().out


@pytest.mark.parametrize("finish_s", [0.0, 8.0])
def test_a_realtime_run_with_finish_s_goes_on_to_its_goal(zenoh_hub, pr2, finish_s) -> None:
    """A real-time run ended at its length, the robot short of its goal (the demo's, at 0.1 of its velocity limits);
    with finish_s it goes on until the goal is reached, and ends there."""
    exec_z = zenoh_hub()
    cfg = ExecutorConfig(mode="realtime", steps=2, step_period_s=0.2, state_rate_hz=50.0, velocity_scale=0.1,
                         finish_s=finish_s, mcap="none", wait_for=["predictor", "planner"])
    fake = FakeSystem(zenoh_hub(), waypoints=20)
    service = ExecutorService(cfg, exec_z, robot=pr2, human=(None, None), scene=SCENE)
    with fake.running(realtime_hz=10.0):
        t = threading.Thread(target=service.run)
        t.start()
        t.join(timeout=30)
        service.stop.set()
        t.join(timeout=10)
    assert not t.is_alive()
    r = service.result
    ran_s = r.times[-1] - r.times[0]  # the states' wall-clock stamps
    assert r.steps == 2
    if finish_s == 0:
        assert not r.reached and r.finish_steps == 0 and ran_s < 0.5
    else:
        assert r.reached and r.finish_steps > 0 and r.reached_step >= 2
        assert 0.4 < ran_s < 0.4 + finish_s  # it ended at the goal, before finish_s ran out


def test_a_ros2_robot_s_messages_go_to_the_log_through_its_guard(tmp_path, pr2, monkeypatch) -> None:
    """The link's recorder was the log's write_ros2 itself: once a full disk had ended the file, sending a command
    raised after it had gone out (the run stopped without a hold) and joint states were dropped (a review)."""
    import services.ros2.link as link_module
    from shared.config import ZenohConfig
    from shared.recording.writer import McapLog

    found: dict[str, object] = {}

    class FoundRobot:  # the link once the robot answered, at its start
        def __init__(self, *args: object) -> None:
            found["record"] = args[-1]

        def initial(self, timeout_s: float) -> np.ndarray:
            return pr2.q_start.numpy().astype(np.float64)

    monkeypatch.setattr(link_module, "Ros2RobotLink", FoundRobot)
    cfg = ExecutorConfig(mode="realtime", robot="ros2", mcap=str(tmp_path / "run.mcap"))
    service = ExecutorService(cfg, ZenohConfig(multicast_scouting=False), robot=pr2, human=(None, None), scene=SCENE)
    service.mcap = McapLog(tmp_path / "run.mcap", service.keys, None)
    service._connect_robot(None)
    record = found["record"]
    clock = ("/clock", "rosgraph_msgs/msg/Clock", bytes([0, 1, 0, 0]) + bytes(8))
    record(*clock)  # type: ignore[operator]
    service.mcap._file._failed = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # past what it holds: ended
    record(*clock)  # type: ignore[operator]
    assert service.result.log_write_failures == 1 and service.mcap.counts == {"/clock": 1}
    service._write(service.mcap.close)  # fails as a full disk's close does: counted, the file closed
    assert service.mcap.closed
