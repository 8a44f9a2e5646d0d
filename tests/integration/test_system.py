"""The four services together over Zenoh on loopback, in one process (issue 5, integration a, c, d, e)."""

from __future__ import annotations

import time

import numpy as np
from mcap.reader import make_reader

from shared.protocol import Plan, decode


def _plans_by_tick(plans: list[Plan]) -> dict[int, Plan]:
    return {p.tick: p for p in plans}


def _mcap_messages(path: str) -> dict[str, list[tuple[str, bytes]]]:
    out: dict[str, list[tuple[str, bytes]]] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append((schema.name if schema else "", message.data))
    return out


def test_lockstep_two_cup_run(run_system):
    system = run_system(mode="lockstep", steps=20)
    result = system.executor_result()
    plans, states, final_occ, posteriors = system.recorder.snapshot()
    by_tick = _plans_by_tick(plans)
    assert sorted(by_tick) == list(range(20)), "one plan per replanning step"
    assert all(p.goal_names == ["blue_cup", "red_cup"] for p in plans)
    assert result.steps == 20
    assert result.reached, "the executed trajectory reaches a goal"
    # the robot stopped at the chosen goal of its last adopted plan, within the joint limits
    limits = system.services["executor"].limits
    q = result.q
    assert np.all(q >= limits.lower - 1e-9) and np.all(q <= limits.upper + 1e-9)
    # Fig. 4: the plan of step n is made with the prediction of step n-1
    assert all(p.occupancy_tick == p.tick - 1 for p in plans if 1 <= p.tick <= 19)
    assert final_occ is not None and posteriors

    channels = _mcap_messages(result.mcap_path)
    keys = system.keys.data_keys()
    del keys[system.keys.keypoints]  # the replayer's system: no sensor (tests/integration/test_tracker.py has one)
    for key, cls in keys.items():
        assert key in channels, f"MCAP lacks channel {key}"
        for schema, data in channels[key]:
            assert schema == f"foresight.{cls.TYPE}"
            decode(data, cls)  # every logged message decodes
    assert len(channels[system.keys.plan]) == 20
    assert any(topic.startswith("/viz/") for topic in channels), "Foxglove scene channels"


def test_lockstep_is_deterministic_and_the_same_with_security(run_system, tmp_path):
    """Two runs, the second with mutual TLS and the generated access control (certificates made here): equal."""
    from shared.security.acl import ROLES
    from shared.security.certificates import init_security_dir

    init_security_dir(tmp_path / "security", ROLES)
    runs = []
    for security in (None, tmp_path / "security"):
        system = run_system(mode="lockstep", steps=8, seed=7, security=security)
        system.executor_result()
        plans, states, _, _ = system.recorder.snapshot()
        runs.append((_plans_by_tick(plans), sorted(states, key=lambda s: s.stamp)))
    (a, sa), (b, sb) = runs
    assert sorted(a) == sorted(b) == list(range(8))
    for tick in a:
        assert a[tick].chosen == b[tick].chosen
        np.testing.assert_array_equal(a[tick].trajectories, b[tick].trajectories)
        np.testing.assert_array_equal(a[tick].cost_total, b[tick].cost_total)
    np.testing.assert_array_equal(np.array([s.q for s in sa]), np.array([s.q for s in sb]))


def test_realtime_executor_holds_without_prediction_and_resumes(run_system, system_files, wait_until):
    # hold_without=[]: the hold comes from the occupancy's age alone (the path where an end marker of the
    # looping human must not release the robot while the prediction is stale, issue 12)
    system = run_system(mode="realtime", steps=0, period=0.3,
                        executor_overrides={"stale_limit_s": 0.5, "wait_for": [], "hold_without": []},
                        replayer_overrides={"loop": True, "rate_hz": 30.0})
    rec = system.recorder

    assert wait_until(lambda: len(rec.snapshot()[0]) >= 2 and not rec.snapshot()[1][-1].holding, 60.0), \
        "the robot moves once plans and predictions flow"
    system.threads["predictor"].stop(timeout=30.0)
    t_stop = time.monotonic()
    # (on a loaded machine the plan may go stale first: the hold that matters names the occupancy)
    assert wait_until(lambda: rec.snapshot()[1][-1].holding and "occupancy" in rec.snapshot()[1][-1].reason, 10.0), \
        "the executor holds without predictions"
    n_held = len(rec.snapshot()[1])
    held = rec.snapshot()[1][-1]
    assert "occupancy" in held.reason and np.all(held.qd == 0.0)
    assert time.monotonic() - t_stop < 5.0
    # the human goes on (end and start markers of the looping replayer): no release while the prediction is stale
    from shared.library import load_library

    demo_s = load_library(system_files.human).demos[0].n_samples / 30.0
    time.sleep(1.5 * demo_s + 0.5)
    during = rec.snapshot()[1][n_held:]
    assert during and all(s.holding for s in during), [s.reason for s in during if not s.holding][:3]
    # bring the predictor back: the executor resumes
    from services.predictor.core import PredictorConfig
    from services.predictor.service import PredictorService

    from .conftest import ServiceThread

    peer = system.services["planner"].zenoh
    model = system.services["predictor"].config.model
    predictor = PredictorService(PredictorConfig(model=model), peer)
    system.threads["predictor"] = ServiceThread("predictor", predictor.run).start()
    assert wait_until(lambda: not rec.snapshot()[1][-1].holding, 30.0), "the executor resumes"
    system.threads["executor"].stop(timeout=30.0)
