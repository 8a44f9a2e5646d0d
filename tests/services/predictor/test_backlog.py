"""The predictor's backlog: bounded, ordered, and a grid only for the newest real-time pose when behind."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from services.predictor.backlog import GridPacer, occupancy_due
from services.predictor.core import PredictorConfig
from services.predictor.service import PredictorService
from shared.config import ZenohConfig
from shared.protocol import ClassPosterior, DemoMarker, HumanPose, Keys, OccupancyGrid
from shared.transport import Presence, TypedPublisher, open_session, subscribe

_NO_ZENOH = ZenohConfig(mode="peer", listen=[], connect=[], multicast_scouting=False)  # never opened by handle()


def _pose(demo_id: int, i: int, f: np.ndarray, tick: int = -1) -> HumanPose:
    return HumanPose(stamp=time.time() if tick < 0 else float(i), tick=tick, tick_last=True, demo_id=demo_id, index=i,
                     features=f)


def _marker(demo_id: int) -> DemoMarker:
    return DemoMarker(stamp=time.time(), tick=-1, demo_id=demo_id, event="start", true_class=0, class_name="x",
                      n_samples=10)


def test_occupancy_due_marks_the_newest_real_time_pose_of_each_run_and_every_lockstep_pose():
    f = np.zeros(12)
    batch = [_pose(1, 0, f), _pose(1, 1, f), _pose(1, 2, f),   # a run of three: the last one
             _marker(2), _pose(2, 0, f),                        # a marker ends a run; a run of one
             _pose(3, 0, f), _pose(3, 1, f),                    # another demonstration: a new run
             _pose(4, 0, f, tick=0), _pose(4, 1, f, tick=0)]    # lock-step: every pose
    assert occupancy_due(batch) == [False, False, True, False, True, False, True, True, True]
    assert occupancy_due([]) == []


def test_a_batch_observes_every_pose_and_predicts_the_newest(small_model, small_library):
    demo = small_library.by_class(1)[0]
    poses = [_pose(7, i, demo.features[i]) for i in range(40)]
    one_by_one = PredictorService(PredictorConfig(), _NO_ZENOH, model=small_model)
    each = [one_by_one.handle(p) for p in poses]
    batched = PredictorService(PredictorConfig(), _NO_ZENOH, model=small_model)
    out = batched.handle_batch(list(poses))
    posts = [m for m in out if isinstance(m, ClassPosterior)]
    grids = [m for m in out if isinstance(m, OccupancyGrid)]
    assert len(posts) == 40 and len(grids) == 1 and grids[0].index == 39
    assert batched.stats.coalesced == 39 and batched.stats.poses == 40
    # no evidence lost: the same posteriors pose by pose, and the same grid for the newest pose
    for p, (q, _) in zip(posts, each, strict=True):
        np.testing.assert_array_equal(p.posterior, q.posterior)
        np.testing.assert_array_equal(p.log_likelihood, q.log_likelihood)
    last = each[-1][1]
    np.testing.assert_array_equal(grids[0].indices, last.indices)
    np.testing.assert_array_equal(grids[0].values, last.values)


def test_a_slow_predictor_publishes_every_posterior_and_grids_for_the_newest_poses(zenoh_hub, small_model,
                                                                                 small_library, monkeypatch,
                                                                                 wait_until):
    svc_cfg, cli_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(cli_cfg.prefix)
    service = PredictorService(PredictorConfig(), svc_cfg, model=small_model)
    predict = service.core.predict

    def slow_predict():  # a grid costs 20 ms: 300 poses sent at once are far ahead of it
        time.sleep(0.02)
        return predict()

    monkeypatch.setattr(service.core, "predict", slow_predict)
    stop, ready = threading.Event(), threading.Event()
    th = threading.Thread(target=service.run, args=(stop, ready), daemon=True)
    th.start()
    grids: list[OccupancyGrid] = []
    posts: list[ClassPosterior] = []
    demo = small_library.by_class(0)[0]
    n = min(300, demo.n_samples)
    try:
        assert ready.wait(15.0)
        with open_session(cli_cfg) as session:
            subs = [subscribe(session, keys.occupancy, OccupancyGrid, grids.append),
                    subscribe(session, keys.posterior, ClassPosterior, posts.append)]
            presence = Presence(session, keys, "tester")
            assert wait_until(lambda: presence.is_alive("predictor"), 10.0, 0.02)
            time.sleep(0.3)
            pub = TypedPublisher(session, keys.pose, block=True)
            for i in range(n):
                pub.put(_pose(3, i, demo.features[i]))
            deadline = time.monotonic() + 20
            while (len(posts) < n or not grids or grids[-1].index != n - 1) and time.monotonic() < deadline:
                time.sleep(0.05)
            for s in subs:
                s.undeclare()
            presence.close()
    finally:
        stop.set()
        th.join(10.0)
    assert not th.is_alive()
    assert [p.index for p in posts] == list(range(n))      # every pose observed, in order
    assert grids and grids[-1].index == n - 1                # the newest pose has its grid
    assert len(grids) < n / 2                                # the others were coalesced, not queued
    assert service.stats.coalesced == n - len(grids)
    assert service.stats.dropped == 0


def test_the_pacer_spaces_grids_and_owes_the_newest_pose_its_grid():
    pacer = GridPacer(0.02)
    assert pacer.due(0.0) and pacer.wait_s(0.0) is None
    pacer.sent(1.0)
    assert not pacer.due(1.01) and pacer.due(1.02)
    pacer.skipped("pose 7")
    assert pacer.owed == "pose 7"
    assert pacer.wait_s(1.005) == pytest.approx(0.015)
    pacer.forget()
    assert pacer.wait_s(1.005) is None
    with pytest.raises(ValueError, match="interval"):
        GridPacer(-1.0)


def test_real_time_grids_are_spaced_and_the_last_pose_still_gets_one(small_model, small_library):
    """300 Hz for 0.3 s (simulated clock): a grid at most every 20 ms, each for the newest pose; the last is flushed."""
    demo = small_library.by_class(2)[0]
    svc = PredictorService(PredictorConfig(grid_interval_s=0.02), _NO_ZENOH, model=small_model)
    grids: list[tuple[float, OccupancyGrid]] = []
    n = min(90, demo.n_samples)
    for i in range(n):
        now = i / 300.0
        grids += [(now, m) for m in svc.handle_batch([_pose(4, i, demo.features[i])], now)
                  if isinstance(m, OccupancyGrid)]
    last_pose_time = (n - 1) / 300.0
    assert not grids or grids[-1][1].index != n - 1  # the last pose came too soon after the previous grid
    assert svc.flush(last_pose_time + 0.001) == [] or len(grids) == 0
    flushed = svc.flush(last_pose_time + 0.02)
    assert len(flushed) == 1 and flushed[0].index == n - 1
    times = [t for t, _ in grids]
    assert all(b - a >= 0.02 - 1e-9 for a, b in zip(times, times[1:], strict=False))
    assert len(grids) + 1 <= n / 6 + 2  # about one grid per 6 poses
    assert svc.stats.coalesced == n - len(grids) - 1 and svc.stats.poses == n
    # the flushed grid is the one a grid per pose would have given for the last pose
    every = PredictorService(PredictorConfig(grid_interval_s=0.0), _NO_ZENOH, model=small_model)
    for i in range(n):
        out = every.handle(_pose(4, i, demo.features[i]))
    np.testing.assert_array_equal(flushed[0].values, out[1].values)
    np.testing.assert_array_equal(flushed[0].indices, out[1].indices)
    # lock-step poses are never paced
    lock = PredictorService(PredictorConfig(grid_interval_s=0.02), _NO_ZENOH, model=small_model)
    outs = lock.handle_batch([_pose(5, i, demo.features[i], tick=0) for i in range(10)], now=0.0)
    assert sum(isinstance(m, OccupancyGrid) for m in outs) == 10


def test_a_refused_pose_at_a_batchs_end_leaves_the_last_pose_taken_owed_its_grid(small_model, small_library):
    """The batch's last pose carries the run's grid; refused, no grid was made for the pose before it, and the
    planner kept an older one until the next valid pose (for good if the stream stopped there): a review."""
    demo = small_library.by_class(0)[0]
    svc = PredictorService(PredictorConfig(grid_interval_s=0.0), _NO_ZENOH, model=small_model)
    svc.handle_batch([_pose(3, 0, demo.features[0])], now=0.0)
    bad = demo.features[2].copy()
    bad[4] = 50.0  # far outside its plausible range: refused
    out = svc.handle_batch([_pose(3, 1, demo.features[1]), _pose(3, 2, bad)], now=1.0)
    assert [type(m).__name__ for m in out] == ["ClassPosterior"] and svc.stats.rejected == 1
    flushed = svc.flush(1.0)
    assert [(type(m).__name__, m.index) for m in flushed] == [("OccupancyGrid", 1)]
    every = PredictorService(PredictorConfig(grid_interval_s=0.0), _NO_ZENOH, model=small_model)
    for i in range(2):
        expected = every.handle(_pose(3, i, demo.features[i]))[1]
    np.testing.assert_array_equal(flushed[0].values, expected.values)
    assert svc.stats.coalesced == 0 and svc.flush(2.0) == []  # it got its grid: nothing more is owed


def test_a_fault_mid_batch_keeps_the_outputs_before_it(small_model, small_library, monkeypatch):
    """A fault of the service (not of the input) at the third of four lock-step poses: the first two's posteriors
    and grids were dropped with the batch, though the model's evidence had taken them."""
    demo = small_library.by_class(0)[0]
    svc = PredictorService(PredictorConfig(), _NO_ZENOH, model=small_model)
    observe = svc.core.observe

    def faulty(features, index=None):
        if index == 2:
            raise RuntimeError("a bug")
        return observe(features, index)

    monkeypatch.setattr(svc.core, "observe", faulty)
    out = svc.handle_batch([_pose(5, i, demo.features[i], tick=i) for i in range(4)], now=0.0)
    assert [(type(m).__name__, m.index) for m in out] == [("ClassPosterior", 0), ("OccupancyGrid", 0),
                                                          ("ClassPosterior", 1), ("OccupancyGrid", 1),
                                                          ("ClassPosterior", 3), ("OccupancyGrid", 3)]
    assert svc.rejects.by_reason == {(svc.keys.pose, "handler"): 1}
