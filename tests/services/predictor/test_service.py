"""The predictor service over real Zenoh on loopback (in-process), and its CLI's bad-input errors."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from services.predictor import service as predictor_service
from services.predictor.__main__ import main as predictor_main
from services.predictor.core import PredictorConfig
from services.predictor.service import PredictorService
from shared.config import ZenohConfig
from shared.protocol import ClassPosterior, DemoMarker, HumanPose, Keys, OccupancyGrid, encode
from shared.transport import Presence, TypedPublisher, open_session, subscribe


class Inbox:
    def __init__(self) -> None:
        self.items: list = []
        self.cond = threading.Condition()

    def add(self, msg) -> None:
        with self.cond:
            self.items.append(msg)
            self.cond.notify_all()

    def wait(self, n: int, timeout: float = 15.0) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: len(self.items) >= n, timeout=timeout)


def _pose(demo_id: int, i: int, f: np.ndarray, tick: int = -1) -> HumanPose:
    stamp = float(i) if tick >= 0 else time.time()  # lock-step: simulated time; real time: the wall clock
    return HumanPose(stamp=stamp, tick=tick, tick_last=True, demo_id=demo_id, index=i, features=f)


@contextlib.contextmanager
def served(service: PredictorService, cli_cfg: Any, wait_until: Any) -> Iterator[tuple[Any, Inbox, Inbox]]:
    """``service`` running on its thread, and a session subscribed to its grids and posteriors once it is seen.

    Yields ``(session, grids, posteriors)``; on exit the subscriptions close and the service stops (bounded).
    """
    keys = Keys(cli_cfg.prefix)
    stop, ready = threading.Event(), threading.Event()
    th = threading.Thread(target=service.run, args=(stop, ready), daemon=True)
    th.start()
    try:
        assert ready.wait(15.0)
        grids, posts = Inbox(), Inbox()
        with open_session(cli_cfg) as session:
            subs = [subscribe(session, keys.occupancy, OccupancyGrid, grids.add),
                    subscribe(session, keys.posterior, ClassPosterior, posts.add)]
            presence = Presence(session, keys, "tester")
            assert wait_until(lambda: presence.is_alive("predictor"), 10.0, 0.02)
            time.sleep(0.3)  # let the subscriptions propagate
            try:
                yield session, grids, posts
            finally:
                for sub in subs:
                    sub.undeclare()
                presence.close()
    finally:
        stop.set()
        th.join(10.0)
    assert not th.is_alive()


def test_service_publishes_grid_per_pose_and_survives_bad_input(zenoh_hub, small_model, small_library,
                                                                 wait_until) -> None:
    svc_cfg, cli_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(cli_cfg.prefix)
    service = PredictorService(PredictorConfig(), svc_cfg, model=small_model)
    with served(service, cli_cfg, wait_until) as (session, grids, posts):
        pose_pub = TypedPublisher(session, keys.pose, block=True)
        demo_pub = TypedPublisher(session, keys.demo, block=True)
        raw = session.declare_publisher(keys.pose)
        demo = small_library.by_class(1)[0]
        n = 30
        demo_pub.put(DemoMarker(stamp=time.time(), tick=-1, demo_id=5, event="start", true_class=1, class_name="x",
                                n_samples=demo.n_samples))
        for i in range(n):
            pose_pub.put(_pose(5, i, demo.features[i], tick=i))
            if i == 10:  # malformed payloads in the middle of the stream
                raw.put(b"\x00garbage")
                bad = bytearray(encode(_pose(5, 999, demo.features[0])))
                raw.put(bytes(bad[:-7]))
        assert grids.wait(n) and posts.wait(n), f"got {len(grids.items)} grids, {len(posts.items)} posteriors"
        time.sleep(0.2)
        assert len(grids.items) == n
        assert [g.index for g in grids.items] == list(range(n))
        assert [g.tick for g in grids.items] == list(range(n))
        assert all(g.demo_id == 5 and g.method == "prediction" for g in grids.items)
        assert tuple(grids.items[0].dims) == small_model.grid.dims
        assert all(np.isclose(p.posterior.sum(), 1.0) for p in posts.items)
        assert service.rejects.total == 2
        # a new demonstration after a start marker starts from scratch
        demo_pub.put(DemoMarker(stamp=time.time(), tick=-1, demo_id=6, event="start", true_class=1, class_name="x",
                                n_samples=demo.n_samples))
        pose_pub.put(_pose(6, 0, demo.features[0]))
        assert posts.wait(n + 1)
        assert posts.items[-1].demo_id == 6
        assert np.allclose(posts.items[-1].log_likelihood, posts.items[0].log_likelihood)
    assert service.stats.resets == 2

def test_cli_missing_model_is_one_line_error(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        predictor_main(["--model", str(tmp_path / "none.npz")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "foresight train" in err[0]
    with pytest.raises(SystemExit) as exc:  # a directory: it said "not found", hiding the model's own reason
        predictor_main(["--model", str(tmp_path), "--zenoh-mode", "peer", "--listen", "tcp/127.0.0.1:0"])
    assert exc.value.code == 2
    assert f"model file '{tmp_path}' is a directory; give the model file itself" in capsys.readouterr().err


def test_a_fault_in_processing_or_publishing_is_logged_counted_and_the_worker_goes_on(
        zenoh_hub, small_model, small_library, wait_until, caplog) -> None:
    """The worker thread used to die on any exception but a PredictorError: no log line, no more grids."""
    svc_cfg, cli_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(cli_cfg.prefix)
    service = PredictorService(PredictorConfig(), svc_cfg, model=small_model)
    handle, log_likelihood = service.handle_batch, service.core.log_likelihood

    def failing_handle(batch, now):
        if any(isinstance(m, HumanPose) and m.index == 3 for m in batch):
            raise RuntimeError("a bug while processing")
        return handle(batch, now)

    def failing_log_likelihood():
        ll = log_likelihood()
        return np.full_like(ll, np.nan) if service.core.n_observed == 6 else ll  # pose 6 (3 was never observed)

    service.handle_batch = failing_handle
    service.core.log_likelihood = failing_log_likelihood
    with served(service, cli_cfg, wait_until) as (session, grids, posts):
        pose_pub = TypedPublisher(session, keys.pose, block=True)
        demo = small_library.by_class(1)[0]
        for i in range(10):
            pose_pub.put(_pose(5, i, demo.features[i], tick=i))
            time.sleep(0.05)  # one pose per batch
        assert grids.wait(9), [g.index for g in grids.items]
        time.sleep(0.3)
    assert [g.index for g in grids.items] == [i for i in range(10) if i != 3]  # pose 3 lost to the fault, said so
    assert [p.index for p in posts.items] == [0, 1, 2, 4, 5, 7, 8, 9]  # 6's posterior broke the wire contract
    assert service.rejects.by_reason == {(keys.pose, "handler"): 1, (keys.posterior, "handler"): 1}
    messages = [r.getMessage() for r in caplog.records if r.exc_info]
    assert any(f"processing 1 message(s) on {keys.pose} failed unexpectedly" in m for m in messages)
    assert any(f"publishing a ClassPosterior on {keys.posterior} failed unexpectedly" in m for m in messages)


def test_a_fault_repeated_on_every_message_is_counted_each_time_with_one_traceback(
        small_model, small_library, wait_until, caplog) -> None:
    """The worker logged a traceback per failing batch and per failing publication: a fault on every pose of a
    30 Hz stream was 30 tracebacks a second (a review). Now one per key; the rest counted."""
    service = PredictorService(PredictorConfig(), ZenohConfig(prefix="fs"), model=small_model)
    features = small_library.by_class(1)[0].features

    def failing_handle(batch, now):
        raise RuntimeError("a bug while processing")

    class FailingPublisher:
        key = "fs/occupancy"

        def put(self, msg) -> None:
            raise RuntimeError("a bug while publishing")

    service.handle_batch = failing_handle
    stop = threading.Event()
    worker = threading.Thread(target=service._drain, args=(stop,), daemon=True)
    with caplog.at_level(logging.WARNING):
        worker.start()
        try:
            for i in range(100):  # one pose a batch: 100 faults
                service.backlog.put(_pose(5, i, features[i % len(features)], tick=i))
                assert wait_until(lambda n=i + 1: service.rejects.total == n, 10.0, 0.001), service.rejects.summary()
            service.handle_batch = lambda batch, now: [SimpleNamespace(TYPE="OccupancyGrid")] * 100
            service._occ_pub = FailingPublisher()  # type: ignore[assignment]
            service.backlog.put(_pose(5, 100, features[0], tick=100))  # one batch, 100 outputs, each failing
            assert wait_until(lambda: service.rejects.total == 200, 10.0), service.rejects.summary()
        finally:
            stop.set()
            worker.join(10.0)
    assert service.rejects.by_reason == {(service.keys.pose, "handler"): 100, ("fs/occupancy", "handler"): 100}
    assert sum(1 for r in caplog.records if r.exc_info) == 2  # one per key


def test_a_worker_still_busy_at_stop_is_said_and_what_it_computes_later_is_not_published(
        zenoh_hub, small_model, small_library, wait_until, caplog, monkeypatch) -> None:
    svc_cfg, cli_cfg = zenoh_hub(), zenoh_hub()
    keys = Keys(cli_cfg.prefix)
    service = PredictorService(PredictorConfig(), svc_cfg, model=small_model)
    monkeypatch.setattr(predictor_service, "WORKER_JOIN_S", 0.2)
    handle, busy, release = service.handle_batch, threading.Event(), threading.Event()

    def slow_handle(batch, now):
        busy.set()
        release.wait(10.0)  # still processing when the service stops
        return handle(batch, now)

    service.handle_batch = slow_handle
    with served(service, cli_cfg, wait_until) as (session, grids, posts):
        TypedPublisher(session, keys.pose, block=True).put(
            _pose(5, 0, small_library.by_class(1)[0].features[0], tick=0))
        assert busy.wait(10.0)
    assert "the worker was still processing 0.2 s after stop" in caplog.text
    release.set()
    time.sleep(0.3)
    assert grids.items == [] and posts.items == [] and service.stats.published == 0


def test_a_prediction_is_stamped_with_the_pose_it_was_made_from(zenoh_hub, small_model, small_library) -> None:
    """A real-time pose that waited 4.7 s in the backlog got a posterior and a grid stamped 'now': every reader
    took a prediction of a 5 s old motion for a fresh one (a Plan is stamped with its input already)."""
    service = PredictorService(PredictorConfig(), zenoh_hub(), model=small_model)
    demo = small_library.by_class(1)[0]
    old = time.time() - 4.7
    outs = service.handle_batch([HumanPose(stamp=old, tick=-1, tick_last=True, demo_id=3, index=0,
                                           features=demo.features[0])], time.monotonic())
    kinds = {type(o).__name__: o.stamp for o in outs}
    assert kinds == {"ClassPosterior": old, "OccupancyGrid": old}


def test_a_start_marker_with_its_first_pose_is_no_backlog_to_warn_of(zenoh_hub, small_model, small_library,
                                                                      caplog) -> None:
    """Every real-time demonstration began with "predictor: 2 messages were waiting; occupancy for the newest pose
    only": its start marker and first pose, taken together (a new user's run of the README's one-service block)."""
    import threading

    service = PredictorService(PredictorConfig(), zenoh_hub(), model=small_model)
    features = small_library.by_class(0)[0].features
    stop = threading.Event()

    def drained(*messages) -> list[str]:
        for m in messages:
            service.backlog.put(m)
        worker = threading.Thread(target=service._drain, args=(stop,))
        with caplog.at_level("WARNING", logger="foresight.predictor"):
            worker.start()
            time.sleep(0.5)
            stop.set()
            worker.join(10.0)
        stop.clear()
        said = [r.getMessage() for r in caplog.records if "were waiting" in r.getMessage()]
        caplog.clear()
        return said

    start = DemoMarker(stamp=time.time(), tick=-1, demo_id=5, event="start", true_class=0, class_name="x", n_samples=0)
    assert drained(start, _pose(5, 0, features[0])) == []
    said = drained(_pose(5, 1, features[1]), _pose(5, 2, features[2]), _pose(5, 3, features[3]))
    assert len(said) == 1 and said[0].startswith("predictor: 3 poses were waiting")


def test_a_demonstration_that_restarts_at_index_0_is_observed_afresh(zenoh_hub, small_model, small_library) -> None:
    """Index 0 again under the same demo_id kept the evidence and the first pose of the first time (the planner,
    executor and gateway place it anew: StreamPlacement), where a new demonstration begins (a review)."""
    service = PredictorService(PredictorConfig(), zenoh_hub(), model=small_model)
    fresh = PredictorService(PredictorConfig(), zenoh_hub(), model=small_model)
    first, second = small_library.by_class(0)[0].features, small_library.by_class(1)[0].features
    for i in range(20):
        service.handle(_pose(3, i, first[i], tick=i))
    for i in range(10):
        post, _ = service.handle(_pose(3, i, second[i], tick=20 + i))
        want, _ = fresh.handle(_pose(3, i, second[i], tick=i))
        np.testing.assert_array_equal(post.posterior, want.posterior)
    assert service.stats.resets == 2 and service.stats.rejected == 0


def test_an_unfamiliar_motion_is_flagged_on_its_posterior_said_once_and_counted(zenoh_hub, two_class_model,
                                                                                 small_library, caplog) -> None:
    """A motion of a class the model never saw got posteriors like any other (one class near 1, no word)."""
    service = PredictorService(PredictorConfig(), zenoh_hub(), model=two_class_model)
    flags = []
    with caplog.at_level("INFO", logger="foresight.predictor"):
        for demo_id, demo in enumerate(small_library.by_class(2)):
            for i, f in enumerate(demo.features):
                post, _grid = service.handle(_pose(demo_id, i, f, tick=i))
                flags.append((demo_id, post.familiar, post.familiarity))
        service.handle(DemoMarker(stamp=0.0, tick=0, demo_id=99, event="start", true_class=0, class_name="x",
                                  n_samples=1))
    unfamiliar = [d for d, familiar, _ in flags if not familiar]
    assert unfamiliar and service.stats.unfamiliar == len(unfamiliar)
    assert all(s < two_class_model.novelty.threshold for _, familiar, s in flags if not familiar)
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warned) == len(set(unfamiliar))  # once per demonstration, however many poses
    assert all("unlike every class" in w and "least unlikely" in w for w in warned)
    said = [r.getMessage() for r in caplog.records if "poses unfamiliar" in r.getMessage()]
    assert len(said) == len(set(unfamiliar))


def test_a_demonstrations_unfamiliar_count_is_said_at_its_end(zenoh_hub, two_class_model, small_library,
                                                              caplog) -> None:
    """The count was said only at the next start or at shutdown: for a live person, maybe minutes later."""
    service = PredictorService(PredictorConfig(), zenoh_hub(), model=two_class_model)
    demo = small_library.by_class(2)[0]  # a class the model never saw
    with caplog.at_level("INFO", logger="foresight.predictor"):
        for i, f in enumerate(demo.features):
            service.handle(_pose(7, i, f, tick=i))
        assert service.stats.unfamiliar > 0
        assert not [r for r in caplog.records if "poses unfamiliar" in r.getMessage()]
        service.handle(DemoMarker(stamp=0.0, tick=0, demo_id=7, event="end", true_class=2, class_name="x",
                                  n_samples=demo.n_samples))
    said = [r.getMessage() for r in caplog.records if "poses unfamiliar" in r.getMessage()]
    assert said == [f"predictor: demo 7: {service.stats.unfamiliar} of {demo.n_samples} poses unfamiliar"]
