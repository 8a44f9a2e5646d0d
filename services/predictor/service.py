"""The predictor's Zenoh loop: poses and demonstration markers in, class posterior and occupancy out."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

import numpy as np

from shared.config import ZenohConfig
from shared.protocol import ClassPosterior, DemoMarker, Expectations, HumanPose, Keys, Message, OccupancyGrid, Receipt
from shared.runtime import wait_for_stop
from shared.scene import load_scene
from shared.transport import Presence, RejectCounter, TypedPublisher, describe, open_session, subscribe_ordered

from .backlog import Backlog, GridPacer, occupancy_due
from .core import PredictorConfig, PredictorCore, PredictorError
from .model import PredictionModel

__all__ = ["PredictorService", "PredictorStats"]

log = logging.getLogger("foresight.predictor")

WORKER_JOIN_S = 10.0
"""Longest wait at stop for the worker to finish the batch it is processing (s)."""


@dataclass
class PredictorStats:
    """What the service did so far."""

    poses: int = 0
    published: int = 0
    resets: int = 0
    rejected: int = 0
    coalesced: int = 0
    dropped: int = 0
    unprocessed: int = 0
    unfamiliar: int = 0  # poses of a motion the model found unfamiliar (services.predictor.novelty)


class PredictorService:
    """Subscribes to HumanPose/DemoMarker, publishes a ClassPosterior for every pose and its OccupancyGrid.

    A start marker resets the core; a pose of another ``demo_id`` than the current one also does
    (so a predictor started mid-stream recovers). ``tick``, ``tick_last``, ``demo_id`` and
    ``index`` are copied from the pose into both outputs.

    Messages go through a bounded :class:`~services.predictor.backlog.Backlog` drained by one worker
    thread. Every pose is observed and gets its posterior; in real time, when poses arrive faster
    than grids are built, only the newest waiting pose gets a grid, and grids are spaced at least
    ``config.grid_interval_s`` apart (a skipped newest pose gets its grid once due); ``stats.coalesced``
    counts the poses that never got their own. In lock-step every pose gets one.

    Args:
        config: Predictor options.
        zenoh_config: Session options.
        model: Trained model (default: loaded from ``config.model``).
    """

    def __init__(self, config: PredictorConfig, zenoh_config: ZenohConfig,
                 model: PredictionModel | None = None) -> None:
        self.config = config
        self.zenoh_config = zenoh_config
        self.model = model if model is not None else PredictionModel.load(config.model)
        self.scene = load_scene(config.scene or None)
        self.core = PredictorCore(self.model, self.scene, config)
        self.model.check_planner_grid(self.scene)  # what it publishes, the planner must take
        self.keys = Keys(zenoh_config.prefix)
        self.rejects = RejectCounter("predictor", known_keys=self.keys.data_keys())
        # values and per-sender order of what arrives; stamps by the message's tick (either mode)
        self.receipt = Receipt(Expectations(clock="auto"))
        self.stats = PredictorStats()
        self.backlog: Backlog[Message] = Backlog(config.backlog)
        self.pacer: GridPacer[HumanPose] = GridPacer(config.grid_interval_s)
        self._lock = threading.Lock()
        self._behind_logged = -1e9
        self._unfamiliar_in_demo = 0  # poses of the current demonstration found unfamiliar (said once it is over)
        self._ungridded: HumanPose | None = None  # the last real-time pose taken, while it has no grid of its own
        self._post_pub: TypedPublisher[ClassPosterior] | None = None
        self._occ_pub: TypedPublisher[OccupancyGrid] | None = None

    def handle(self, msg: Message) -> tuple[ClassPosterior, OccupancyGrid] | None:
        """Process one incoming message; returns the outputs for a pose (None for a marker or a reject)."""
        with self._lock:
            out = self._process(msg, grid=True, now=None)
        return (out[0], out[1]) if len(out) == 2 else None  # type: ignore[return-value]

    def handle_batch(self, batch: list[Message], now: float | None = None) -> list[ClassPosterior | OccupancyGrid]:
        """Process messages in arrival order; the outputs, in order.

        Real-time grids only where :func:`occupancy_due` says and the pacer allows at ``now``
        (monotonic s; None: no pacing).
        """
        out: list[ClassPosterior | OccupancyGrid] = []
        with self._lock:
            for msg, grid in zip(batch, occupancy_due(batch), strict=True):
                try:
                    out.extend(self._process(msg, grid, now))
                except Exception as exc:  # a fault of this service: the outputs of the messages before it stand
                    self.rejects.unexpected(self.keys.pose, exc, f"processing a {getattr(msg, 'TYPE', 'message')}")
        return out

    def flush(self, now: float) -> list[OccupancyGrid]:
        """The grid owed to the newest real-time pose, once the pacer says it is due ([] otherwise)."""
        with self._lock:
            msg = self.pacer.owed
            if msg is None or not self.pacer.due(now):
                return []
            self.pacer.sent(now)
            self.stats.coalesced -= 1  # it gets its own grid after all
            return [self._grid(msg, msg.stamp)]

    def _grid(self, msg: HumanPose, stamp: float) -> OccupancyGrid:
        return self.core.predict().to_message(stamp=stamp, tick=msg.tick, tick_last=msg.tick_last,
                                              demo_id=msg.demo_id, index=msg.index)

    def _reset(self, demo_id: int) -> None:
        self._say_unfamiliar()
        self.core.reset(demo_id)
        self.pacer.forget()  # a grid owed to the old demonstration is void
        self._ungridded = None
        self.stats.resets += 1

    def _process(self, msg: Message, grid: bool, now: float | None) -> list[ClassPosterior | OccupancyGrid]:
        if isinstance(msg, DemoMarker):
            if msg.event == "start":
                self._reset(msg.demo_id)
                log.info("predictor: demo %d start (%s)", msg.demo_id, msg.class_name)
            elif msg.event == "lost":  # its last grid stands; the executor holds the robot until a demonstration starts
                log.info("predictor: demo %d lost by the tracker after %d poses", msg.demo_id, msg.n_samples)
            if msg.event in ("end", "lost") and msg.demo_id == self.core.demo_id:
                self._say_unfamiliar()  # at its end, not at the next start (a live person's may be minutes later)
            return []
        assert isinstance(msg, HumanPose)
        if msg.demo_id != self.core.demo_id or (msg.index == 0 and self.core.n_observed):
            self._reset(msg.demo_id)  # index 0 again: the demonstration restarts (StreamPlacement places it anew too)
        try:
            posterior = self.core.observe(msg.features, msg.index)
        except PredictorError as exc:
            self.rejects.reject(self.keys.pose, exc)
            self.stats.rejected += 1
            if grid and msg.tick < 0 and self._ungridded is not None:  # it was to carry the run's grid: the last
                self.pacer.skipped(self._ungridded)  # pose taken is owed one (flush), as the newest pose always is
                self._ungridded = None
            return []
        self.stats.poses += 1
        if not self.core.familiar:
            self._unfamiliar(msg, posterior)
        # stamped with the pose it was predicted from, as a Plan is with its input: a pose that waited in the backlog
        # gives a prediction as old as it (stamped 'now', a 5 s old pose's grid looked fresh to every reader)
        stamp = msg.stamp
        out: list[ClassPosterior | OccupancyGrid] = [
            ClassPosterior(stamp=stamp, tick=msg.tick, demo_id=msg.demo_id, index=msg.index,
                           class_names=list(self.model.class_names), posterior=posterior,
                           log_likelihood=self.core.log_likelihood(), familiar=self.core.familiar,
                           familiarity=self.core.familiarity)]
        realtime = msg.tick < 0
        if realtime:
            self.pacer.forget()  # a newer pose supersedes the owed one
        if grid and realtime and now is not None and not self.pacer.due(now):
            grid = False
            self.pacer.skipped(msg)
        if grid:
            out.append(self._grid(msg, stamp))
            if realtime and now is not None:
                self.pacer.sent(now)
        else:
            self.stats.coalesced += 1
        self._ungridded = msg if realtime and not grid else None
        return out

    def _unfamiliar(self, pose: HumanPose, posterior: np.ndarray) -> None:
        """Count an unfamiliar pose; the demonstration's first is said at once, with what it means."""
        self.stats.unfamiliar += 1
        self._unfamiliar_in_demo += 1
        if self._unfamiliar_in_demo == 1:
            best = int(np.argmax(posterior))
            novelty = self.core.novelty
            assert novelty is not None  # without a novelty test every motion is familiar
            log.warning("predictor: demo %d: the motion is unlike every class from sample %d on (familiarity %.1f "
                        "below the model's threshold %.1f nats/frame; the posterior's best, %s at %.2f, is only the "
                        "least unlikely); occupancy %s", pose.demo_id, pose.index, self.core.familiarity,
                        novelty.threshold, self.model.class_names[best], float(posterior[best]),
                        "of every class at once" if self.config.unfamiliar == "all-classes" else
                        "from the posterior as ever (predictor.unfamiliar = all-classes keeps every class's volume)")

    def _say_unfamiliar(self) -> None:
        """At the end of a demonstration with unfamiliar poses: how many."""
        if self._unfamiliar_in_demo:
            log.info("predictor: demo %d: %d of %d poses unfamiliar", self.core.demo_id, self._unfamiliar_in_demo,
                     self.core.n_observed)
        self._unfamiliar_in_demo = 0

    def _on_message(self, msg: Message) -> None:
        self.backlog.put(msg)  # on Zenoh's thread: never block it

    def _drain(self, stop: threading.Event) -> None:
        """The worker: process what waits, publish the outputs, until ``stop``."""
        while not stop.is_set():
            owed = self.pacer.wait_s(time.monotonic())
            batch = self.backlog.take_all(0.1 if owed is None else min(0.1, owed))
            now = time.monotonic()
            streaming = any(isinstance(m, HumanPose) and m.tick < 0 for m in batch)
            try:
                outs = self.handle_batch(batch, now) if batch else []
                if not streaming:
                    outs += self.flush(now)  # the stream paused: the newest pose gets its grid once due
            except Exception as exc:  # a fault of this service, not of the input: counted (traceback once), goes on
                self.rejects.unexpected(self.keys.pose, exc, f"processing {len(batch)} message(s)")
                outs = []
            for out in outs:
                pub = self._post_pub if isinstance(out, ClassPosterior) else self._occ_pub
                if pub is None:
                    continue
                try:
                    pub.put(out)  # encodes: a message that breaks the wire contract is refused here
                except Exception as exc:
                    self.rejects.unexpected(pub.key, exc, f"publishing a {out.TYPE}")
                    continue
                self.stats.published += isinstance(out, OccupancyGrid)
            self.stats.dropped = self.backlog.dropped
            waiting = sum(isinstance(m, HumanPose) for m in batch)  # a start marker with its first pose is no backlog
            if waiting > 1 and streaming and now - self._behind_logged > 5.0:
                self._behind_logged = now  # behind: said at most every 5 s
                log.warning("predictor: %d poses were waiting; occupancy for the newest pose only "
                            "(%d poses without their own grid so far, %d dropped from a full backlog)",
                            waiting, self.stats.coalesced, self.stats.dropped)

    def run(self, stop: threading.Event | None = None, ready: threading.Event | None = None) -> PredictorStats:
        """Serve until ``stop`` is set; ``ready`` is set once subscribed and announced."""
        stop = stop or threading.Event()
        with open_session(self.zenoh_config, stop, "predictor") as session:
            # reliable: a lock-step tick's last grid must never be dropped (the worker publishes in bursts)
            self._post_pub = TypedPublisher(session, self.keys.posterior, block=True)
            self._occ_pub = TypedPublisher(session, self.keys.occupancy, block=True)
            types = {self.keys.pose: HumanPose, self.keys.demo: DemoMarker}
            sub = subscribe_ordered(session, self.keys.human_all, types, self._on_message, self.rejects,
                                    self.receipt)
            presence = Presence(session, self.keys, "predictor", stop_with=self.config.stop_with, stop=stop)
            log.info("predictor: model %s (%d classes, grid %s at %g m, features %s, %s, %s), method %s, scene %s, "
                     "session %s", self.config.model, self.model.n_classes, self.model.grid.dims,
                     self.model.grid.resolution, self.model.feature_variant, self.model.describe_time(),
                     self.model.novelty.describe() if self.model.novelty is not None else
                     "no novelty test: every motion is called familiar (retrain to learn one)",
                     self.config.method, self.scene.name, describe(session)["zid"])
            worker = threading.Thread(target=self._drain, args=(stop,), name="predictor-worker", daemon=True)
            worker.start()
            if ready is not None:
                ready.set()
            try:
                wait_for_stop(stop)
            finally:
                presence.close()
                sub.undeclare()
                self.backlog.wake()
                worker.join(WORKER_JOIN_S)
                if worker.is_alive():  # its outputs from now on find no publisher: dropped, and said so
                    log.warning("predictor: the worker was still processing %g s after stop; what it still "
                                "computes is not published", WORKER_JOIN_S)
                self.stats.dropped = self.backlog.dropped
                self.stats.unprocessed = len(self.backlog)  # arrived, never processed: stopped first
                self._post_pub.undeclare()
                self._occ_pub.undeclare()
                self._post_pub = self._occ_pub = None
        self._say_unfamiliar()
        log.info("predictor: stopped after %d poses (%d grids published, %d poses without their own grid while "
                 "behind, %d dropped from a full backlog, %d left unprocessed at stop, %d resets, %d unfamiliar, "
                 "%d rejected: %s)", self.stats.poses, self.stats.published, self.stats.coalesced, self.stats.dropped,
                 self.stats.unprocessed, self.stats.resets, self.stats.unfamiliar, self.rejects.total,
                 self.rejects.summary())
        return self.stats
