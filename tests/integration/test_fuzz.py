"""Fuzz of the running system on every key (issue 12): no crash, every refusal counted, none logged as data.

The four services run in-process over loopback Zenoh in real time (the replayer looping), as in
``test_system.py``. A fuzzer session publishes, on every data key, ``FORESIGHT_FUZZ_COUNT`` rounds
(default 240) of random, truncated, bit-flipped, wrong-schema, oversized (declared and real) and
well-formed-but-absurd payloads (see ``fuzzing.py``). Then:

* every service is still running;
* the executor refused every payload that is not a plausible message, each counted under its key
  with a reason (the deterministic ones under the expected reason), and wrote it to the MCAP's
  rejects channel, never to the key's data channel; what it accepted from the fuzzer are only bit
  flips and order anchors that are plausible messages;
* the planner and the predictor refused at least the payloads any receiver must refuse;
* genuine traffic flows on every key afterwards (accepted and logged after the fuzz);
* the process's resident memory (all four services) is reported, and loosely bounded.

``FORESIGHT_FUZZ_COUNT=10000`` runs the long version (outside CI).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections import Counter

import pytest
import zenoh

from shared.protocol import REASONS, Expectations, ProtocolError, Receipt
from shared.recording.reader import read_log
from shared.recording.schemas import REJECTED_TOPIC
from shared.transport import open_session, sender_of

from .fuzzing import Fuzzer, clock_template

COUNT = int(os.environ.get("FORESIGHT_FUZZ_COUNT", "240"))
RSS_GROWTH_LIMIT_MB = 1024.0
"""A loose bound: the fuzz must not leave the process (four services) this much larger."""


def rss_mb() -> float:
    """Resident memory of this process (MB), from /proc."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")  # pragma: no cover - Linux only


def wait_until(pred, timeout: float, step: float = 0.05) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return bool(pred())


def settle(total, timeout: float = 300.0, quiet_s: float = 2.0) -> None:
    """Wait until ``total()`` has not changed for ``quiet_s`` seconds."""
    end = time.monotonic() + timeout
    last, since = total(), time.monotonic()
    while time.monotonic() < end:
        time.sleep(0.2)
        now = total()
        if now != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return


@pytest.mark.slow
def test_fuzz_every_key_of_a_running_system(run_system, record_property):
    system = run_system(mode="realtime", steps=0, period=0.3,
                        executor_overrides={"wait_for": [], "stale_limit_s": 1.0},
                        replayer_overrides={"loop": True, "rate_hz": 30.0})
    keys = system.keys
    executor, planner, predictor = (system.services[n] for n in ("executor", "planner", "predictor"))
    genuine: dict[str, object] = {}
    accepted_at: dict[str, float] = {}  # arrival of the newest genuine message per key, checked as a service would
    checks = Receipt(Expectations(clock="realtime", robot=planner.receipt.expect.robot,
                                  grid=planner.receipt.expect.grid))

    def watch(sample) -> None:
        key, sender = str(sample.key_expr), sender_of(sample)
        if key not in keys.data_keys() or not sender:  # the fuzzer publishes without a sender id
            return
        try:
            msg = checks.accept(key, sample.payload.to_bytes(), keys.data_keys()[key], sender)
        except ProtocolError:
            return
        genuine[key] = msg
        accepted_at[key] = time.time()

    with open_session(planner.zenoh) as session:
        watcher = session.declare_subscriber(f"{keys.prefix}/**", watch)
        flowing = {keys.pose, keys.demo, keys.posterior, keys.occupancy, keys.plan, keys.robot_state}
        assert wait_until(lambda: flowing <= set(genuine), 120.0), f"the system runs: {sorted(genuine)}"
        templates = {k: genuine[k] for k in flowing} | {keys.clock: clock_template()}
        assert set(templates) == set(keys.data_keys())
        fuzzers = {k: Fuzzer(m, [o for kk, o in templates.items() if kk != k], seed=i)
                   for i, (k, m) in enumerate(templates.items())}
        pubs = {k: session.declare_publisher(k, congestion_control=zenoh.CongestionControl.BLOCK) for k in templates}
        time.sleep(1.0)
        rss_before = rss_mb()
        sent: dict[str, list] = {k: [] for k in templates}
        for i in range(COUNT):
            for k, fz in fuzzers.items():
                for case in fz.cases(i):
                    pubs[k].put(case.payload)
                    sent[k].append((case.digest, case.must_refuse, case.category, case.name, case.reason))
            if i % 20 == 19:
                time.sleep(0.02)  # the genuine traffic keeps flowing in between
        t_fuzz_end = time.time()
        settle(lambda: executor.rejects.total)
        # genuine traffic accepted on every key after the fuzz (the clock ticks only in lock-step)
        assert wait_until(lambda: all(accepted_at[k] > t_fuzz_end + 1.0 for k in flowing), 60.0), \
            f"genuine traffic after the fuzz (s after its end): { {k: accepted_at[k] - t_fuzz_end for k in flowing} }"
        time.sleep(4.0)  # a loop of the demonstration: markers too
        rss_after = rss_mb()
        alive = {name: t.thread.is_alive() and t.error is None for name, t in system.threads.items()}
        watcher.undeclare()
        for p in pubs.values():
            p.undeclare()
    assert all(alive.values()), f"services alive after the fuzz: {alive}"
    result = system.threads["executor"].stop(timeout=60.0)

    log = read_log(result.mcap_path, keep=lambda c: True)
    data = {k: {} for k in templates}
    after = Counter()
    for m in log.messages:
        if m.topic in data:
            data[m.topic][hashlib.sha1(m.data).digest()] = m.log_time
            if m.log_time / 1e9 > t_fuzz_end:
                after[m.topic] += 1
    records = [json.loads(m.data) for m in log.messages if m.topic == REJECTED_TOPIC]

    by_reason = executor.rejects.by_reason
    report = {}
    for k, cases in sent.items():
        accepted = [c for c in cases if c[0] in data[k]]
        refused_by_design = [c for c in cases if c[1]]
        assert not [c for c in accepted if c[1]], f"{k}: a payload that must be refused was logged as data"
        assert {c[2] for c in accepted} <= {"bitflip", "order"}, f"{k}: only bit flips and anchors may pass"
        n_rej = executor.rejects.counts.get(k, 0)
        expected = len(cases) - len(accepted)
        if k in (keys.posterior, keys.occupancy):
            # the predictor has no clock mode: a lock-step-stamped pose it accepted from the fuzzer comes
            # out as a lock-step-stamped prediction, which the real-time executor refuses (mismatch)
            assert expected <= n_rej <= expected + by_reason.get((k, "mismatch"), 0), k
        else:
            assert n_rej == expected, f"{k}: {n_rej} refused, {len(cases)} sent, {len(accepted)} logged as data"
        want = Counter(c[4] for c in refused_by_design if c[4])
        for reason, n in want.items():
            assert by_reason.get((k, reason), 0) >= n, f"{k}: {reason} counted {by_reason.get((k, reason), 0)} < {n}"
        assert sum(1 for r in records if r["key"] == k) == n_rej, f"{k}: rejects channel"
        assert after[k] > 0 or k == keys.clock, f"{k}: no genuine message logged after the fuzz"
        report[k] = {"sent": len(cases), "refused": n_rej, "accepted_from_fuzzer": len(accepted),
                     "reasons": {r: n for (kk, r), n in sorted(by_reason.items()) if kk == k}}
    assert {r["reason"] for r in records} <= set(REASONS)
    # the other receivers refused at least what any receiver must refuse
    must = {k: sum(1 for c in cases if c[1] and c[4] not in (None, "mismatch")) for k, cases in sent.items()}
    for svc, ks in ((planner, (keys.robot_state, keys.occupancy, keys.demo)), (predictor, (keys.pose, keys.demo))):
        for k in ks:
            assert svc.rejects.counts.get(k, 0) >= must[k], f"{svc.rejects.service} on {k}"
    info = {"count_per_key": COUNT, "rss_before_mb": round(rss_before, 1), "rss_after_mb": round(rss_after, 1),
            "per_key": report, "planner": planner.rejects.summary(), "predictor": predictor.rejects.summary()}
    record_property("fuzz", info)
    print("FUZZ", json.dumps(info, indent=1))
    assert rss_after - rss_before < RSS_GROWTH_LIMIT_MB, f"RSS grew {rss_after - rss_before:.0f} MB"
