"""Fuzz of the running system on every key (issue 12): no crash, every refusal counted, none logged as data.

The four services run in-process over loopback Zenoh, as in ``test_system.py``. A fuzzer session
publishes, on every data key, rounds of random, truncated, bit-flipped, wrong-schema, oversized
(declared and real) and well-formed-but-absurd payloads (``fuzzing.py``). In real time (replayer
looping), ``FORESIGHT_TEST_FUZZ_COUNT`` rounds (default 240):

* every service is still running;
* the executor refused every payload that is not a plausible message, each counted under its key
  with a reason (the deterministic ones under the expected reason), and wrote it to the MCAP's
  rejects channel, never to the key's data channel; only bit flips and order anchors that are
  plausible messages were accepted from the fuzzer;
* the planner and the predictor refused at least the payloads any receiver must refuse;
* genuine traffic is accepted on every key after the fuzz;
* the process's resident memory (all four services) is reported, and loosely bounded.

During a lock-step run, the payloads every receiver refuses whatever its clock: the run completes
with a plan per tick, every service refused each payload on its keys, and clock ticks flow after
the fuzz. ``test_fuzz_processes.py`` runs the real-time fuzz against separate processes.
"""

from __future__ import annotations

import hashlib
import json
import os
import time

import numpy as np
import pytest

from shared.protocol import DemoMarker, Expectations, decode
from shared.recording.reader import read_log
from shared.transport import open_session

from .fuzz_checks import (
    Watcher,
    check_executor_log,
    fuzz_session,
    must_refuse_anywhere,
    problems_of,
    publish_fuzz,
    rss_mb,
    settle,
    wait_until,
)
from .fuzzing import Case, clock_template

COUNT = int(os.environ.get("FORESIGHT_TEST_FUZZ_COUNT", "240"))
RSS_GROWTH_LIMIT_MB = 1024.0
"""A loose bound: the fuzz must not leave the process (four services) this much larger."""


@pytest.mark.slow
def test_fuzz_every_key_of_a_running_system(run_system, record_property):
    system = run_system(mode="realtime", steps=0, period=0.3,
                        executor_overrides={"wait_for": [], "stale_limit_s": 1.0},
                        replayer_overrides={"loop": True, "rate_hz": 30.0})
    keys = system.keys
    executor, planner, predictor = (system.services[n] for n in ("executor", "planner", "predictor"))
    flowing = set(keys.data_keys()) - {keys.clock, keys.keypoints}  # the clock ticks only in lock-step; no sensor
    with open_session(planner.zenoh) as session:
        watch = Watcher(session, keys, Expectations(clock="realtime", robot=planner.receipt.expect.robot,
                                                     grid=planner.receipt.expect.grid))
        assert wait_until(lambda: flowing <= set(watch.latest), 120.0), f"the system runs: {sorted(watch.latest)}"
        templates = {k: watch.latest[k] for k in flowing} | {keys.clock: clock_template()}
        time.sleep(1.0)
        rss_before = rss_mb()
        with fuzz_session(planner.zenoh) as fz:  # every clock tick is refused in real time: a progress count
            sent = publish_fuzz(fz, templates, COUNT, progress=lambda: executor.rejects.counts.get(keys.clock, 0),
                                pace_key=keys.clock)
        t_fuzz_end = time.time()
        settle(lambda: executor.rejects.total)
        assert wait_until(lambda: all(watch.accepted_at[k] > t_fuzz_end + 1.0 for k in flowing), 60.0), \
            f"genuine traffic after the fuzz (end + s): { {k: watch.accepted_at[k] - t_fuzz_end for k in flowing} }"
        time.sleep(4.0)  # a loop of the demonstration: markers too
        rss_after = rss_mb()
        alive = {name: t.thread.is_alive() and t.error is None for name, t in system.threads.items()}
        watch.close()
    assert all(alive.values()), f"services alive after the fuzz: {alive}"
    result = system.threads["executor"].stop(timeout=60.0)
    report = check_executor_log(result.mcap_path, keys, sent, t_fuzz_end, executor.rejects.counts,
                                executor.rejects.by_reason)
    info = {"count_per_key": COUNT, "rss_before_mb": round(rss_before, 1), "rss_after_mb": round(rss_after, 1),
            "per_key": report, "planner": planner.rejects.summary(), "predictor": predictor.rejects.summary()}
    record_property("fuzz", info)
    print("FUZZ", json.dumps(info, indent=1))
    assert not problems_of(report), problems_of(report)
    must = must_refuse_anywhere(sent)
    for svc, ks in ((planner, (keys.robot_state, keys.occupancy, keys.demo)), (predictor, (keys.pose, keys.demo))):
        for k in ks:
            assert svc.rejects.counts.get(k, 0) >= must[k], f"{svc.rejects.service} on {k}"
    assert rss_after - rss_before < RSS_GROWTH_LIMIT_MB, f"RSS grew {rss_after - rss_before:.0f} MB"


LOCKSTEP_ROUNDS = 60
"""Rounds per key of the lock-step fuzz (it runs while the lock-step run goes on)."""


def refused_in_any_mode(case: Case) -> bool:
    """Cases every receiver refuses whatever its clock: no bit flips or anchors, no mode-dependent stamps."""
    return (case.must_refuse and case.category not in ("bitflip", "order") and case.name != "16 MiB"
            and case.reason not in ("mismatch", "stamp-past"))


@pytest.mark.slow
def test_fuzz_every_key_during_a_lockstep_run(run_system):
    steps = 12
    clean = run_system(mode="lockstep", steps=steps).executor_result()  # the same run without the fuzz
    assert clean.steps == steps and all(g >= 0 for g in clean.goal_per_step[1:]) and np.ptp(clean.q, 0).max() > 0.1
    system = run_system(mode="lockstep", steps=steps)
    keys, rec = system.keys, system.recorder
    executor = system.services["executor"]
    genuine: dict[str, bytes] = {}
    with open_session(system.services["planner"].zenoh) as session:
        watcher = session.declare_subscriber(
            f"{keys.prefix}/**", lambda s: genuine.setdefault(str(s.key_expr), s.payload.to_bytes()))
        # the start marker may have gone before we listened; the replayer's system has no sensor
        needed = set(keys.data_keys()) - {keys.demo, keys.keypoints}
        assert wait_until(lambda: needed <= set(genuine) and len(rec.snapshot()[0]) >= 2, 240.0), \
            f"the run goes: {sorted(genuine)}"
        templates = {k: decode(genuine[k], cls) for k, cls in keys.data_keys().items() if k in genuine}
        pose = templates[keys.pose]
        templates.setdefault(keys.demo, DemoMarker(stamp=pose.stamp, tick=pose.tick, demo_id=pose.demo_id,
                                                   event="end", true_class=1, class_name="red_cup", n_samples=100))
        t_fuzz_start = time.time()
        with fuzz_session(system.services["planner"].zenoh) as fz:
            sent = publish_fuzz(fz, templates, LOCKSTEP_ROUNDS, seed=10, keep=refused_in_any_mode,
                                progress=lambda: executor.rejects.counts.get(keys.clock, 0), pace_key=keys.clock)
        result = system.executor_result()
        watcher.undeclare()
    assert {p.tick for p in rec.snapshot()[0]} == set(range(steps)), "the run completes with a plan per step"
    # every fuzz case must be refused, so the run is the clean one (lock-step, seeded), to the bit
    assert result.goal_per_step == clean.goal_per_step and result.reached == clean.reached
    np.testing.assert_array_equal(result.q, clean.q)
    probes = {k: sum(1 for c in cases if c.category == "probe") for k, cases in sent.items()}
    fuzz = {k: [c for c in cases if c.category != "probe"] for k, cases in sent.items()}
    for k, cases in fuzz.items():  # probes (before the fuzz, to find the route) may or may not arrive
        assert len(cases) <= executor.rejects.counts.get(k, 0) <= len(cases) + probes[k], \
            f"{k}: {len(cases)} sent, refused {executor.rejects.summary()}"
    log = read_log(result.mcap_path, keep=lambda c: True)
    logged = {(m.topic, hashlib.sha1(m.data).digest()) for m in log.messages if m.topic in sent}
    assert not logged & {(k, c.digest) for k, cases in fuzz.items() for c in cases}, "a fuzz payload was logged"
    ticks = [m.log_time / 1e9 for m in log.messages if m.topic == keys.clock]
    # the run goes on through the fuzz: ticks after it or, when the run (asserted complete above) ends first on a
    # fast machine, its last tick during it
    assert ticks and max(ticks) > t_fuzz_start, "clock ticks flow (and are answered) during the fuzz"
    for name, keys_of in (("planner", (keys.robot_state, keys.occupancy, keys.clock, keys.demo)),
                          ("predictor", (keys.pose, keys.demo)), ("replayer", (keys.clock,))):
        counts = system.services[name].rejects.counts
        for k in keys_of:
            assert len(fuzz[k]) <= counts.get(k, 0) <= len(fuzz[k]) + probes[k], \
                f"{name} on {k}: {counts.get(k, 0)} of {len(fuzz[k])}"
