"""The system as processes under faults and a 300 Hz pose stream (issue 12, items 5 and 6).

One real-time run (router + four services as processes, loopback, every process stopped with a
bounded timeout): a few seconds of poses (nothing crashes, the numbers are finite; 30 Hz: at 300 Hz
on a loaded 2-core machine the executor's own delivery lags, see ``foresight bench soak``), then
SIGKILL of the predictor while the robot moves (the robot holds before the predictor is back, never
moves while it is down, and moves again after its return), then SIGKILL of the executor (its MCAP
reads back up to the last complete chunk). Events are checked in order, never against a time limit;
``foresight bench faults`` and ``foresight bench soak`` measure the latencies.
"""

from __future__ import annotations

import math

import pytest

from shared.recording.reader import read_log
from tools.faults import demo_model, measure_kill, recover_after_kill
from tools.log.info import format_info
from tools.soak import soak
from tools.system import ProcessSystem, SystemSpec, Watcher


@pytest.mark.slow
def test_soak_then_kill_the_predictor_then_the_executor(tmp_path):
    spec = SystemSpec(run_dir=tmp_path / "run", model=demo_model(tmp_path / "models", components=3), rate_hz=30.0)
    system = ProcessSystem(spec)
    try:
        with Watcher(system.endpoint, poses=True) as watcher:
            system.start_all()
            r = soak(system, watcher, duration_s=4.0, timeout=300.0)
            assert all(r["running"].values()), r["running"]
            assert r["poses"] > 0 and r["occupancy_received"] > 0 and r["plans"] > 0
            assert all(v is None or math.isfinite(v) for v in r["latency_s"].values())
            assert r["reaction_latency_s"]["p50"] is not None and math.isfinite(r["reaction_latency_s"]["p50"])
            assert all(m["end"] > 0 for m in r["rss_mb"].values())

            k = measure_kill(system, watcher, "predictor", down_s=2.0, timeout=300.0)
            names = [e for e, _ in k["events"]]
            assert names.index("kill") < names.index("hold") < names.index("restart"), k
            assert names.index("back") < names.index("resume"), k
            assert k["hold_reason"].startswith(("predictor gone", "occupancy is", "plan is")), k
            assert k["moved_while_down"] == 0, k

            m = recover_after_kill(system)
    finally:
        system.close()
    assert not m["complete"] and m["messages"] > 0 and m["channels"] > 0, m
    text = format_info(read_log(spec.mcap_path))
    assert f"recovered {m['messages']} messages" in text
