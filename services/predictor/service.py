"""The predictor's Zenoh loop: poses and demonstration markers in, class posterior and occupancy out."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

from shared.config import ZenohConfig
from shared.protocol import ClassPosterior, DemoMarker, Expectations, HumanPose, Keys, Message, OccupancyGrid, Receipt
from shared.scene import load_scene
from shared.transport import Presence, RejectCounter, TypedPublisher, describe, open_session, subscribe_ordered

from .core import PredictorConfig, PredictorCore, PredictorError
from .model import PredictionModel

__all__ = ["PredictorService", "PredictorStats"]

log = logging.getLogger("foresight.predictor")


@dataclass
class PredictorStats:
    """What the service did so far."""

    poses: int = 0
    published: int = 0
    resets: int = 0
    rejected: int = 0


class PredictorService:
    """Subscribes to HumanPose/DemoMarker, publishes ClassPosterior and OccupancyGrid for every pose.

    A start marker resets the core; a pose of another ``demo_id`` than the current one also does
    (so a predictor started mid-stream recovers). ``tick``, ``tick_last``, ``demo_id`` and
    ``index`` are copied from the pose into both outputs.

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
        self.keys = Keys(zenoh_config.prefix)
        self.rejects = RejectCounter("predictor")
        # values and per-sender order of what arrives; stamps by the message's tick (either mode)
        self.receipt = Receipt(Expectations(clock="auto"))
        self.stats = PredictorStats()
        self._lock = threading.Lock()
        self._post_pub: TypedPublisher[ClassPosterior] | None = None
        self._occ_pub: TypedPublisher[OccupancyGrid] | None = None

    def handle(self, msg: Message) -> tuple[ClassPosterior, OccupancyGrid] | None:
        """Process one incoming message; returns the outputs for a pose (None for a marker or a reject)."""
        with self._lock:
            if isinstance(msg, DemoMarker):
                if msg.event == "start":
                    self.core.reset(msg.demo_id)
                    self.stats.resets += 1
                    log.info("predictor: demo %d start (%s)", msg.demo_id, msg.class_name)
                return None
            assert isinstance(msg, HumanPose)
            if msg.demo_id != self.core.demo_id:
                self.core.reset(msg.demo_id)
                self.stats.resets += 1
            try:
                res = self.core.update(msg.features, msg.index)
            except PredictorError as exc:
                self.rejects.reject(self.keys.pose, exc)
                self.stats.rejected += 1
                return None
            self.stats.poses += 1
            stamp = time.time() if msg.tick < 0 else msg.stamp
            post = ClassPosterior(stamp=stamp, tick=msg.tick, demo_id=msg.demo_id, index=msg.index,
                                  class_names=list(self.model.class_names), posterior=res.posterior,
                                  log_likelihood=res.log_likelihood)
            occ = res.to_message(stamp=stamp, tick=msg.tick, tick_last=msg.tick_last, demo_id=msg.demo_id,
                                 index=msg.index)
            return post, occ

    def _on_message(self, msg: Message) -> None:
        out = self.handle(msg)
        if out is None or self._post_pub is None or self._occ_pub is None:
            return
        post, occ = out
        self._post_pub.put(post)
        self._occ_pub.put(occ)
        self.stats.published += 1

    def run(self, stop: threading.Event | None = None, ready: threading.Event | None = None) -> PredictorStats:
        """Serve until ``stop`` is set; ``ready`` is set once subscribed and announced."""
        stop = stop or threading.Event()
        with open_session(self.zenoh_config, stop, "predictor") as session:
            self._post_pub = TypedPublisher(session, self.keys.posterior)
            self._occ_pub = TypedPublisher(session, self.keys.occupancy)
            types = {self.keys.pose: HumanPose, self.keys.demo: DemoMarker}
            sub = subscribe_ordered(session, self.keys.human_all, types, self._on_message, self.rejects,
                                    self.receipt)
            presence = Presence(session, self.keys, "predictor", stop_with=self.config.stop_with, stop=stop)
            log.info("predictor: model %s (%d classes, grid %s at %g m, features %s), method %s, scene %s, session %s",
                     self.config.model, self.model.n_classes, self.model.grid.dims, self.model.grid.resolution,
                     self.model.feature_variant, self.config.method, self.scene.name, describe(session)["zid"])
            if ready is not None:
                ready.set()
            try:
                stop.wait()
            finally:
                presence.close()
                sub.undeclare()
                self._post_pub.undeclare()
                self._occ_pub.undeclare()
                self._post_pub = self._occ_pub = None
        log.info("predictor: stopped after %d poses (%d published, %d resets, %d rejected: %s)", self.stats.poses,
                 self.stats.published, self.stats.resets, self.rejects.total, self.rejects.summary())
        return self.stats
