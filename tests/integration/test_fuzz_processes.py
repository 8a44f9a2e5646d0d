"""The real-time fuzz against the four services as separate processes: per-service RSS, exit status, counts.

Opt-in (``FORESIGHT_TEST_FUZZ_PROCESSES=1``; ``FORESIGHT_TEST_FUZZ_COUNT`` rounds per key, default 240): the
in-process ``test_fuzz.py`` checks the same in CI. Here each service is ``python -m services.<name>``
connected to this test's Zenoh session on loopback, so a crash is a dead process and each
service's resident memory is its own. The executor's refusals come from its MCAP (metadata and the
rejects channel), the planner's and the predictor's from their shutdown lines.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from services.processes import ServiceProcess, free_port
from shared.config import ZenohConfig
from shared.protocol import Expectations, GridSpec, Keys, RobotSpec
from shared.recording.reader import read_log
from shared.scene import load_scene
from shared.transport import Presence

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
from .fuzzing import clock_template

COUNT = int(os.environ.get("FORESIGHT_TEST_FUZZ_COUNT", "240"))
RSS_GROWTH_LIMIT_MB = 512.0
"""A loose bound per service."""

pytestmark = pytest.mark.skipif(not os.environ.get("FORESIGHT_TEST_FUZZ_PROCESSES"),
                                reason="opt-in: FORESIGHT_TEST_FUZZ_PROCESSES=1 (test_fuzz.py covers it in-process)")


def parse_summary(log_text: str) -> dict[tuple[str, str], int]:
    """``(key, reason) -> n`` from the last ``rejected: <summary>`` of a service's output."""
    lines = [ln for ln in log_text.splitlines() if "rejected: " in ln and ("stopped" in ln or "done after" in ln)]
    if not lines:
        return {}
    text = lines[-1].rsplit("rejected: ", 1)[-1].strip().rstrip(")")
    out: dict[tuple[str, str], int] = {}
    for part in text.split("; "):
        if part == "none" or ": " not in part:
            continue
        key, reasons = part.split(": ", 1)
        for item in reasons.split(", "):
            reason, n = item.rsplit(" ", 1)
            out[(key, reason)] = int(n)
    return out


def test_fuzz_against_service_processes(system_files, tmp_path: Path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hub = ZenohConfig(mode="peer", listen=[endpoint], connect=[], multicast_scouting=False)
    keys = Keys(hub.prefix)
    common = ["--connect", endpoint, "--listen", "tcp/127.0.0.1:0", "--zenoh-mode", "peer", "--log-level", "INFO"]
    mcap = tmp_path / "fuzz.mcap"
    args = {
        "predictor": ["--model", str(system_files.model), *common],
        "planner": ["--mode", "realtime", "--period-s", "0.3", "--lookahead-s", "0.3", "--no-compile",
                    "--stomp.iterations", "20", *common],
        "replayer": ["--library", str(system_files.human), "--mode", "realtime", "--loop", "--rate-hz", "30", *common],
        "executor": ["--mode", "realtime", "--steps", "0", "--step-period-s", "0.3", "--stale-limit-s", "1.0",
                     "--wait-for", "", "--mcap", str(mcap), *common],
    }
    procs = {n: ServiceProcess(n, f"services.{n}", a, tmp_path / f"{n}.log") for n, a in args.items()}
    from shared.robot import PR2

    scene = load_scene()
    expect = Expectations(clock="realtime", robot=RobotSpec.from_robot(PR2.from_scene(scene)),
                          grid=GridSpec.from_grid(scene.grid))
    flowing = set(keys.data_keys()) - {keys.clock, keys.keypoints}  # no sensor in the replayer's system
    with fuzz_session(hub) as session:  # the hub (the services connect to it) publishes the fuzz, too
        presence = Presence(session, keys, "fuzzer")
        watch = Watcher(session, keys, expect)
        try:
            for p in procs.values():
                p.start()
            for p in procs.values():
                p.wait_alive(presence.is_alive, 180.0)
            assert wait_until(lambda: flowing <= set(watch.latest), 180.0), f"the system runs: {sorted(watch.latest)}"
            templates = {k: watch.latest[k] for k in flowing} | {keys.clock: clock_template()}
            time.sleep(2.0)
            rss_before = {n: rss_mb(p.proc.pid) for n, p in procs.items()}
            t0 = time.time()
            sent = publish_fuzz(session, templates, COUNT)
            t_fuzz_end = time.time()
            ex_log = procs["executor"].log_path
            settle(lambda: ex_log.read_text(errors="replace").count("rejected a message"), quiet_s=3.0)
            assert wait_until(lambda: all(watch.accepted_at[k] > t_fuzz_end + 1.0 for k in flowing), 120.0), \
                f"genuine traffic after the fuzz (end + s): { {k: watch.accepted_at[k] - t_fuzz_end for k in flowing} }"
            time.sleep(4.0)
            alive = {n: p.running for n, p in procs.items()}
            rss_after = {n: rss_mb(p.proc.pid) if p.running else float("nan") for n, p in procs.items()}
        finally:
            codes = {n: procs[n].stop(timeout=30.0) for n in ("executor", "replayer", "planner", "predictor")}
            watch.close()
            presence.close()
    lf = read_log(mcap)
    counts = {k: int(v) for k, v in lf.metadata["foresight.rejects"].items()}
    by_reason = {tuple(k.rsplit(" ", 1)): int(v) for k, v in lf.metadata["foresight.rejects.reasons"].items()}
    # unpaced against separate processes, the executor can fall minutes behind (reported as "late")
    report = check_executor_log(str(mcap), keys, sent, t_fuzz_end, counts, by_reason, late_ok=True)
    must = must_refuse_anywhere(sent)
    others = {n: parse_summary(procs[n].log_path.read_text(errors="replace")) for n in ("planner", "predictor")}
    info = {"count_per_key": COUNT, "fuzz_s": round(t_fuzz_end - t0, 1), "rss_before_mb": rss_before,
            "rss_after_mb": rss_after, "alive": alive, "exit": codes, "per_key": report,
            "planner": {f"{k} {r}": n for (k, r), n in sorted(others["planner"].items())},
            "predictor": {f"{k} {r}": n for (k, r), n in sorted(others["predictor"].items())}}
    print("FUZZ", json.dumps(info, indent=1))
    assert all(alive.values()), f"services alive after the fuzz: {alive}"
    assert all(c == 0 for c in codes.values()), f"exit status after SIGTERM: {codes}"
    assert not problems_of(report), problems_of(report)
    for name, ks in (("planner", (keys.robot_state, keys.occupancy, keys.demo)), ("predictor", (keys.pose, keys.demo))):
        for k in ks:
            got = sum(n for (kk, _), n in others[name].items() if kk == k)
            assert got >= must[k], f"{name} on {k}: {got} < {must[k]}"
    for n in procs:
        assert rss_after[n] - rss_before[n] < RSS_GROWTH_LIMIT_MB, f"{n}: RSS {rss_before[n]} -> {rss_after[n]} MB"
