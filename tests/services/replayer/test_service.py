"""The replayer over real Zenoh on loopback: in-process (real time, lock-step) and as a subprocess."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from services.replayer.__main__ import main as replayer_main
from services.replayer.core import ReplayerConfig
from services.replayer.service import ReplayerService
from shared.library import save_library
from shared.protocol import ClockTick, DemoMarker, HumanPose, Keys
from shared.transport import Presence, TypedPublisher, open_session, subscribe_ordered
from tools.foresight import main as foresight_main

REPO = Path(__file__).resolve().parents[3]


class Collector:
    """Subscribes to poses and markers; keeps them in arrival order."""

    def __init__(self, session, keys: Keys) -> None:
        self.items: list = []
        self.cond = threading.Condition()
        self.sub = subscribe_ordered(session, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker},
                                     self.add)

    def add(self, msg) -> None:
        with self.cond:
            self.items.append(msg)
            self.cond.notify_all()

    def poses(self) -> list[HumanPose]:
        with self.cond:
            return [m for m in self.items if isinstance(m, HumanPose)]

    def wait(self, predicate, timeout: float = 10.0) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: predicate(self.items), timeout=timeout)


def ends(n: int):
    return lambda items: sum(isinstance(m, DemoMarker) and m.event == "end" for m in items) >= n


def check_stream(items: list, demos) -> None:
    """Markers and poses of ``demos`` arrived complete and in order."""
    i = 0
    for demo_id, d in enumerate(demos):
        start = items[i]
        assert isinstance(start, DemoMarker) and (start.event, start.demo_id, start.true_class) == (
            "start", demo_id, d.label)
        poses = items[i + 1:i + 1 + d.n_samples]
        assert all(isinstance(p, HumanPose) and p.demo_id == demo_id for p in poses)
        assert [p.index for p in poses] == list(range(d.n_samples))
        np.testing.assert_array_equal(np.stack([p.features for p in poses]), d.features)
        end = items[i + 1 + d.n_samples]
        assert isinstance(end, DemoMarker) and (end.event, end.demo_id) == ("end", demo_id)
        i += d.n_samples + 2
    assert i == len(items)


def run_in_thread(service: ReplayerService, stop: threading.Event) -> threading.Thread:
    th = threading.Thread(target=service.run, args=(stop,), daemon=True)
    th.start()
    return th


def test_realtime_every_pose_in_order(zenoh_hub, small_lib):
    sub_cfg, rep_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(sub_cfg.prefix)
    cfg = ReplayerConfig(rate_hz=400.0, classes=[0, 2], indices=[1, 2], wait_for=["predictor"], wait_timeout=10.0)
    service = ReplayerService(cfg, rep_cfg, small_lib)
    with open_session(sub_cfg) as session:
        col = Collector(session, keys)
        presence = Presence(session, keys, "predictor")  # the peer it waits for
        stop = threading.Event()
        th = run_in_thread(service, stop)
        assert col.wait(ends(4), timeout=20.0), f"received {len(col.items)} messages"
        th.join(timeout=10.0)
        assert not th.is_alive()
        presence.close()
    assert service.stats.finished and service.stats.demos == 4
    check_stream(col.items, service.demos)
    assert [(d.label, d.index) for d in service.demos] == [(0, 1), (0, 2), (2, 1), (2, 2)]


def test_lockstep_replayer_stops_with_the_executor(zenoh_hub, small_lib, caplog):
    """``stop_with=[executor]``: the run's master ends before the demonstrations do; the replayer ends too."""
    sub_cfg, rep_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(sub_cfg.prefix)
    service = ReplayerService(ReplayerConfig(mode="lockstep", stop_with=["executor"]), rep_cfg, small_lib)
    stop = threading.Event()
    caplog.set_level(logging.INFO, logger="shared.transport")
    with open_session(sub_cfg) as session:
        presence = Presence(session, keys, "executor")
        th = run_in_thread(service, stop)
        deadline = time.monotonic() + 10
        # the replayer stops when a peer it has seen goes: wait until it has seen the executor, not only until the
        # executor sees it (under load its liveliness history arrived after the token was gone: it never stopped)
        while not any(r.getMessage() == "replayer: peer executor appeared" for r in caplog.records):
            assert time.monotonic() < deadline, "the replayer never saw the executor"
            time.sleep(0.01)
        TypedPublisher(session, keys.clock).put(ClockTick(stamp=0.0, tick=0, period=0.2))
        presence.close()  # the executor is done after one tick
        th.join(timeout=10.0)
        alive = th.is_alive()
        ended_by_presence = stop.is_set()
        stop.set()
    assert not alive and ended_by_presence
    assert not service.stats.finished  # ended by the executor's departure, not by the end of the stream



def _waiting_lines(service: ReplayerService, caplog) -> list[logging.LogRecord]:
    """Run a lock-step replayer that gets no tick until it says it waits (10 s at most); its 'no clock tick' lines."""
    stop = threading.Event()
    th = run_in_thread(service, stop)
    deadline = time.monotonic() + 10
    while not any("no clock tick on" in r.getMessage() for r in caplog.records) and time.monotonic() < deadline:
        time.sleep(0.05)
    stop.set()
    th.join(timeout=10.0)
    assert not th.is_alive()
    return [r for r in caplog.records if "no clock tick on" in r.getMessage()]


def test_a_lockstep_replayer_with_no_clock_says_it_waits(zenoh_hub, small_lib, caplog, monkeypatch):
    """With no executor ticking it waited for ever, saying only its start line."""
    import services.replayer.service as replayer_service

    monkeypatch.setattr(replayer_service, "NO_TICK_WARN_S", 0.3)
    caplog.set_level(logging.WARNING, logger="foresight.replayer")
    said = _waiting_lines(ReplayerService(ReplayerConfig(mode="lockstep"), zenoh_hub(), small_lib), caplog)
    assert said and "publishes a pose only when the executor ticks" in said[0].getMessage()


def test_a_lockstep_replayer_waiting_while_the_executor_is_up_says_it_is_no_fault(zenoh_hub, small_lib, caplog,
                                                                                   monkeypatch):
    """The executor waits for its services before the first tick (a planner compiles for up to a minute on a first
    `docker compose up`): the replayer's warning asked whether an executor was running while one was."""
    import services.replayer.service as replayer_service

    monkeypatch.setattr(replayer_service, "NO_TICK_WARN_S", 1.0)  # the executor's token is seen well before
    caplog.set_level(logging.INFO, logger="foresight.replayer")
    executor_cfg = zenoh_hub()
    with open_session(executor_cfg) as session:
        executor = Presence(session, Keys(executor_cfg.prefix), "executor")
        said = _waiting_lines(ReplayerService(ReplayerConfig(mode="lockstep"), zenoh_hub(), small_lib), caplog)
        executor.close()
    assert said and said[0].levelno == logging.INFO and "the executor is up" in said[0].getMessage()


def test_lockstep_driven_by_clock_ticks(zenoh_hub, small_lib):
    sub_cfg, rep_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(sub_cfg.prefix)
    cfg = ReplayerConfig(mode="lockstep", samples_per_tick=5, classes=[1], indices=[0, 3])
    service = ReplayerService(cfg, rep_cfg, small_lib)
    total = sum(d.n_samples for d in service.demos)  # 12 + 15
    stop = threading.Event()
    with open_session(sub_cfg) as session:
        col = Collector(session, keys)
        presence = Presence(session, keys, "executor")
        th = run_in_thread(service, stop)
        deadline = time.monotonic() + 10
        while not presence.is_alive("replayer"):
            assert time.monotonic() < deadline, "replayer never appeared"
            time.sleep(0.01)
        clock = TypedPublisher(session, keys.clock)
        session.put(keys.clock, b"not msgpack at all")  # rejected, counted, ignored
        n_ticks = -(-total // 5)
        for n in range(n_ticks):
            time.sleep(0.005)
            assert not col.poses() or col.poses()[-1].tick == n - 1
            clock.put(ClockTick(stamp=0.5 * n, tick=n, period=0.5))  # the contract: stamp = tick x period
            assert col.wait(lambda items, n=n: any(isinstance(m, HumanPose) and m.tick == n and m.tick_last
                                                   for m in items), timeout=10.0), f"tick {n}"
        assert col.wait(ends(2), timeout=5.0)
        th.join(timeout=10.0)
        assert not th.is_alive()
        presence.close()
    check_stream(col.items, service.demos)
    poses = col.poses()
    assert [p.tick for p in poses] == [k // 5 for k in range(total)]
    assert [p.tick_last for p in poses] == [(k % 5 == 4 or k == total - 1) for k in range(total)]
    np.testing.assert_allclose([p.stamp for p in poses], [0.5 * (k // 5) + 0.1 * (k % 5) for k in range(total)])
    assert service.stats.ticks == n_ticks and service.rejects.total == 1


def _spawn(args: list[str]) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "services.replayer", *args], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _stop(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> tuple[int, str]:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate(timeout=5)
        pytest.fail(f"replayer did not stop within {timeout} s after signal {sig}:\n{err}")
    return proc.returncode, err


def test_subprocess_replayer(zenoh_hub, small_lib, tmp_path):
    """python -m services.replayer in its own process; poses received here; SIGTERM stops it cleanly."""
    save_library(small_lib, tmp_path / "lib.npz")
    sub_cfg = zenoh_hub()
    keys = Keys(sub_cfg.prefix)
    with open_session(sub_cfg) as session:
        col = Collector(session, keys)
        presence = Presence(session, keys, "predictor")  # the peer it waits for
        proc = _spawn(["--library", str(tmp_path / "lib.npz"), "--classes", "2", "--rate-hz", "300", "--loop",
                       "--wait-for", "predictor", "--listen", "tcp/127.0.0.1:0", "--connect", sub_cfg.listen[0]])
        try:
            ok = col.wait(ends(5), timeout=30.0)
        finally:
            code, err = _stop(proc)
        presence.close()
    assert ok, f"received {len(col.items)} messages; replayer stderr:\n{err}"
    assert code == 0, err
    assert "Traceback" not in err
    demos = [d for d in small_lib.demos if d.label == 2]
    n_full = 5
    items = []
    for m in col.items:  # the first 5 demonstrations (looping over the 4 of class 2)
        if isinstance(m, DemoMarker) and m.event == "start" and m.demo_id >= n_full:
            break
        items.append(m)
    check_stream(items, [demos[k % 4] for k in range(n_full)])


def test_subprocess_bad_input_one_line(tmp_path):
    for args, pattern in ((["--library", str(tmp_path / "missing")], "missing' not found"),
                          (["--rate-hz", "-3", "--library", str(tmp_path)], "rate_hz: must be in [0.01, 10000]")):
        proc = _spawn(args)
        try:
            _, err = proc.communicate(timeout=30.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate(timeout=5.0)
            pytest.fail(f"replayer {args} did not exit on bad input")
        code = proc.returncode
        assert code == 2, err
        assert err.strip().count("\n") == 0 and pattern in err and "Traceback" not in err, err


def test_help_lists_every_option(capsys):
    import dataclasses

    from shared.config import ZENOH_FLAG_NAMES, ZenohConfig

    with pytest.raises(SystemExit) as e:
        foresight_main(["replayer", "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for f in dataclasses.fields(ReplayerConfig):
        assert "--" + f.name.replace("_", "-") in out, f.name
    for f in dataclasses.fields(ZenohConfig):  # a Zenoh option's flag may differ from its field (--security)
        assert "--" + ZENOH_FLAG_NAMES.get(f.name, f.name).replace("_", "-") in out, f.name
    assert foresight_main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in ("replayer", "router", "library"):
        assert command in out


def test_bad_option_value_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        replayer_main(["--samples-per-tick", "two"], prog="foresight replayer")
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err == "foresight replayer: error: --samples-per-tick: expected int, got 'two'"
    with pytest.raises(SystemExit) as e:
        replayer_main(["--mode", "fast"], prog="foresight replayer")
    assert "--mode: 'fast' is not one of realtime, lockstep" in capsys.readouterr().err
