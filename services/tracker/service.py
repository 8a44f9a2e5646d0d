"""The tracker's Zenoh loop: keypoint frames in (Foresight's key or ROS 2), ``HumanPose`` and ``DemoMarker`` out.

Each frame is checked on receipt (``shared.protocol.Receipt``: form, coordinates within range of the sensor,
frame numbers increasing per sender) and queued (:class:`shared.backlog.Backlog`); a worker takes the waiting
frames through :class:`~services.tracker.core.TrackerCore` under a lock, thinned when they span too long to
catch up (:mod:`.catch_up`; counted, and said once). Before, Zenoh's thread fitted every frame in turn, and with a
sensor faster than the fit the poses fell behind the person by seconds, with no word said. A refused frame gets
one logged line and is counted (per reason, in the shutdown line); nothing of it is published. With
``--from FILE`` the service plays a keypoint recording on the keypoints key in real time from a session of its
own that presents the ``sensor`` role, so the frames take the same way as a sensor driver's
(:mod:`services.tracker.playback`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from shared.backlog import Backlog
from shared.config import ConfigError, ZenohConfig
from shared.human import HumanModel
from shared.human_source import HumanPublisher
from shared.keypoints.library import read_keypoint_csv
from shared.keypoints.plausibility import recording_problem
from shared.protocol import (
    AT_REST,
    SENSOR,
    DemoMarker,
    Expectations,
    HumanKeypoints,
    HumanPose,
    Keys,
    ProtocolError,
    Receipt,
)
from shared.transport import Presence, RejectCounter, TypedPublisher, describe, open_session, subscribe

from .catch_up import frames_to_fit
from .config import TrackerServiceConfig
from .core import REASONS, TrackerCore
from .playback import Playback

__all__ = ["TrackerService", "TrackerStats", "NODE_NAME", "BACKLOG_LIMIT"]

log = logging.getLogger("foresight.tracker")

NODE_NAME = "foresight_tracker"
"""The tracker's ROS 2 node name (input ros2)."""
BACKLOG_LIMIT = 1024
"""Most frames waiting for the worker (4 s of a 240 Hz sensor); beyond it the oldest are dropped and counted."""
REFUSAL_LOG_PERIOD_S = 1.0
"""At most one log line per refusal reason in this time (every refusal is counted)."""


@dataclass
class TrackerStats:
    """What a run took in and gave out."""

    frames: int = 0
    poses: int = 0
    markers: int = 0
    reaches: int = 0
    rests: int = 0  # the person seen at rest, published (services.tracker.demos)
    played: int = 0
    behind: int = 0  # frames left unfitted to catch up (catch_up), or dropped by a full backlog
    failed: int = 0  # batches whose processing raised (the first one's traceback logged)
    refused: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REASONS, 0))


class TrackerService:
    """A live person's keypoints -> the human's poses and reach markers on Foresight's keys.

    Args:
        config: The service's, the core's and the playback's options.
        zenoh_config: Session options (endpoints, prefix, security).
        model: The human model (default: ``HumanModel()``).

    Raises:
        ConfigError: ``--from`` names a file that is no keypoint recording, or a player without a router to reach.
    """

    def __init__(self, config: TrackerServiceConfig, zenoh_config: ZenohConfig,
                 model: HumanModel | None = None) -> None:
        config.validate()
        self.config = config
        self.zenoh_config = zenoh_config
        self.keys = Keys(zenoh_config.prefix)
        self.core = TrackerCore(config.tracker, model)
        self.stats = TrackerStats()
        self.rejects = RejectCounter("tracker", known_keys=self.keys.data_keys())
        self._lock = threading.Lock()
        self._ros2_frame = 0
        self._accepted_at = time.monotonic()  # when the core last took a frame (check_silence)
        self._refusal_logged: dict[str, float] = {}  # reason -> when a refusal of it was last logged
        self._ros2_receipt = Receipt(Expectations(clock="realtime"))
        self.backlog: Backlog[tuple[HumanKeypoints, bool]] = Backlog(BACKLOG_LIMIT)
        self._working = False  # the worker is inside a batch (check_silence waits for it)
        self._human: HumanPublisher | None = None
        self.playback: Playback | None = None
        if config.from_file is not None:
            try:
                recorded = read_keypoint_csv(config.from_file)
                self.playback = Playback(recorded, config.playback)
            except ValueError as exc:
                raise ConfigError(f"tracker.from_file: {exc}") from None
            layout, names = self.core.layout, self.playback.names
            unknown = layout.unknown(names)
            lacking = layout.lacking(names)
            if unknown or lacking:  # every frame would be refused, and the run end as if it had played
                raise ConfigError(f"tracker.from_file: {config.from_file} does not fit the layout {layout.name}: "
                                  + (f"points {unknown[:4]} are not the layout's" if unknown else
                                     f"it cannot form the required {lacking}") + " (tracker.layout)")
            for demo in recorded:  # else every frame is refused (on receipt, upright, missing), and the run ends 0
                if problem := recording_problem(layout, demo.names, demo.positions):  # as library from-keypoints
                    raise ConfigError(f"tracker.from_file: {config.from_file} demo {demo.demo}: {problem}")
            if not zenoh_config.connect:
                raise ConfigError("tracker.from_file: the player connects to the router in zenoh.connect; none given")

    # -- frames ------------------------------------------------------------------------------------------------

    def on_keypoints(self, msg: HumanKeypoints, numbered: bool = True, fit: bool = True) -> None:
        """One checked frame: through the core, its messages published, a refusal logged and counted.

        ``numbered``: ``msg.frame`` is the sensor's own frame number (a gap is a dropped frame); a ROS 2 frame
        has none, its number only counts arrivals. ``fit`` False: a frame left unfitted to catch up.
        """
        with self._lock:
            self.stats.frames += 1
            out = self.core.on_keypoints(msg, numbered, fit)
            if out.refused is not None:
                reason, now = out.refused.split(":", 1)[0], time.monotonic()
                if now - self._refusal_logged.get(reason, -math.inf) >= REFUSAL_LOG_PERIOD_S:  # a sensor with no
                    self._refusal_logged[reason] = now  # one in view refuses 30 frames a second: one line a second
                    log.warning("tracker: frame %d refused (%s); refused so far: %s", msg.frame, out.refused,
                                ", ".join(f"{k} {v}" for k, v in self.core.refused.items() if v))
                return
            self._accepted_at = time.monotonic()
            if out.note:
                log.info("tracker: %s", out.note)
            self._publish(out.messages)

    def check_silence(self) -> bool:
        """End the reach under way if no frame was taken for longer than ``max_gap_s``; whether it did.

        The sensor stopped, or every frame is refused: the reach ends now, at its last frame, while its end marker
        is fresh for the receivers (they refuse old stamps). The core alone would end it only when the next frame
        comes, which may be minutes later.
        """
        with self._lock:
            quiet = time.monotonic() - self._accepted_at
            if not self.core.tracking or quiet <= self.config.tracker.max_gap_s or len(self.backlog) or self._working:
                return False  # frames that may continue the reach are waiting for the worker: no silence
            self._publish(self.core.finish().messages)
        log.info("tracker: no frame taken for %.1f s: starting afresh with the next", quiet)
        return True

    def _on_peer(self, peer: str, appeared: bool) -> None:
        """An executor (re)appeared: the person at rest is said again (:meth:`Demonstrations.say_again`)."""
        if peer == "executor" and appeared:
            with self._lock:
                if self.core.tracking:
                    self.core.demos.say_again()
                    log.info("tracker: an executor appeared: the person is said again once seen at rest")

    def _publish(self, messages: list) -> None:
        """The core's poses and markers on their keys (under the lock)."""
        if not messages:
            return
        human = self._human
        assert human is not None
        for m in messages:
            assert isinstance(m, HumanPose | DemoMarker)
            human.put(m)
            if isinstance(m, DemoMarker) and m.class_name == AT_REST:
                if m.event == "end":
                    log.info("tracker: the person is seen at rest (demonstration %d, %d poses at %.3f): the predictor "
                             "predicts from there until a reach starts", m.demo_id, m.n_samples, m.stamp)
            elif isinstance(m, DemoMarker) and m.event == "start":
                log.info("tracker: reach %d starts (its first pose at %.3f)", m.demo_id, m.stamp)
            elif isinstance(m, DemoMarker) and m.event == "lost":
                what = f"the person at rest (demonstration {m.demo_id})" if m.class_name == AT_REST else \
                    f"reach {m.demo_id}"
                log.warning("tracker: %s lost at %.3f after %d poses (no frame for over %g s, another body, moved "
                            "away, or the tracker stopping): the executor holds the robot until the person is seen "
                            "again", what, m.stamp, m.n_samples, self.config.tracker.max_gap_s)
            elif isinstance(m, DemoMarker):
                log.info("tracker: reach %d ends at %.3f after %d poses", m.demo_id, m.stamp, m.n_samples)
        self.stats.poses, self.stats.markers = human.poses, human.markers
        self.stats.reaches, self.stats.rests = self.core.demos.reaches, self.core.demos.rests

    def _on_pose_array(self, mapping: Any, names: list[str], payload: bytes) -> None:
        """A ROS 2 ``PoseArray``: as a ``HumanKeypoints`` frame, checked like one off Foresight's key."""
        from services.ros2.core import KEYPOINTS_TYPE, Ros2InputError
        from services.ros2.keypoints import keypoints_in

        try:
            stamp, frame_id, positions = keypoints_in(mapping, payload, len(names))  # Ros2InputError: counted
        except Ros2InputError as exc:
            if len(mapping.decode(payload, KEYPOINTS_TYPE).poses) == len(names):  # (not the CDR: raises again)
                raise
            # another count of poses: a driver with more or fewer points than the order taken (the layout's own)
            now = ",".join(names) if len(",".join(names)) <= 120 else f"{','.join(names[:5])},... ({len(names)})"
            raise Ros2InputError(f"{exc}: pose i is --ros2-points[i], now {now}; set it to the driver's names in its "
                                 "pose order") from None  # the reject line shows 300 characters: the advice in them
        msg = HumanKeypoints(stamp=stamp or time.time(), tick=-1, frame=self._ros2_frame, frame_id=frame_id,
                             names=names, positions=positions)
        self._ros2_frame += 1
        msg.check()  # ProtocolError (a ValueError): refused and counted by the node
        self._ros2_receipt.check(self.config.ros2_topic, msg)
        self.backlog.put((msg, False))

    def work(self, batch: list[tuple[HumanKeypoints, bool]]) -> None:
        """Frames taken from the backlog (oldest first) through :meth:`on_keypoints`, thinned if they span too long.

        ``batch``: ``(frame, numbered)`` pairs.
        """
        spacing = self.config.tracker.max_gap_s / 3
        keep = set(frames_to_fit([m.stamp for m, _ in batch], spacing))
        if len(keep) < len(batch):
            if not self.stats.behind:
                log.info("tracker: the fit fell behind the sensor (%d frames waiting): fitting %d of them, at most "
                         "%.2f s apart, to catch up (the others are counted, not fitted)", len(batch), len(keep),
                         spacing)
            self.stats.behind += len(batch) - len(keep)
        self._working = True
        try:
            for i, (msg, numbered) in enumerate(batch):
                self.on_keypoints(msg, numbered, fit=i in keep)
        finally:
            self._working = False

    def _work(self, stop: threading.Event) -> None:
        """The worker: the backlog's frames through :meth:`work`, until ``stop``; a frame's failure is logged."""
        while not stop.is_set():
            if batch := self.backlog.take_all(0.1):
                self._work_safely(batch)

    def _work_safely(self, batch: list[tuple[HumanKeypoints, bool]]) -> None:
        try:
            self.work(batch)
        except Exception as exc:  # a bug on one batch must not end the worker: every later frame would wait unfitted
            self.stats.failed += 1  # counted under reason handler, its traceback once (not one a batch, 30 a second)
            key = self.config.ros2_topic if self.config.input == "ros2" else self.keys.keypoints
            self.rejects.unexpected(key, exc, f"fitting a batch of {len(batch)} frames")

    # -- the loop ----------------------------------------------------------------------------------------------

    def run(self, stop: threading.Event | None = None) -> TrackerStats:
        """Serve until ``stop`` is set (or, with ``--from`` and no loop, shortly after the recording ends)."""
        stop = stop or threading.Event()
        cfg = self.config
        with open_session(self.zenoh_config, stop, "tracker") as session:
            self._human = HumanPublisher(session, self.keys)
            done = threading.Event()
            worker = threading.Thread(target=self._work, args=(done,), name="tracker-fit", daemon=True)
            worker.start()
            closers = self._inputs(session)
            presence = Presence(session, self.keys, "tracker", on_change=self._on_peer, stop_with=cfg.stop_with,
                                stop=stop)
            log.info("tracker: %s keypoints (layout %s, frame %s) -> %s, session %s", self._source(),
                     cfg.tracker.layout, cfg.tracker.frame_id, self.keys.pose, describe(session)["zid"])
            try:
                if self.playback is not None:
                    presence.wait_for(cfg.wait_for, cfg.wait_timeout, stop)
                    self._play(self.playback, stop)
                    stop.wait(0.5)  # the last frames' poses and markers are delivered
                else:
                    while not stop.wait(min(0.1, cfg.tracker.max_gap_s / 3)):
                        self.check_silence()
            finally:
                for close in closers:
                    close()
                done.set()
                self.backlog.wake()
                worker.join(timeout=10.0)
                if left := self.backlog.take_all(0.0):  # the last frames received, not yet fitted
                    self._work_safely(left)
                with self._lock:  # no frame comes any more: the person is lost (at a recording's end, only a reach)
                    last = self.core.finish(recording_ended=self.playback is not None).messages
                    self._publish(last)
                if last:
                    time.sleep(0.2)  # delivered before the session closes
                presence.close()
        self.stats.refused, self.stats.behind = dict(self.core.refused), self.stats.behind + self.backlog.dropped
        log.info("tracker: stopped after %d frames (%d played; %d skipped over max_fit_hz, %d unfitted or dropped to "
                 "catch up), "
                 "%d reaches (%d lost), seen at rest %d times, lost after an end %d times (out of view or moved "
                 "away), %d poses, %d markers; refused: %s; "
                 "optional points left out, far off the fit: %d; rejected on receipt: %s", self.stats.frames,
                 self.stats.played, self.core.skipped, self.stats.behind, self.stats.reaches, self.core.demos.lost,
                 self.stats.rests, self.core.demos.unseen, self.stats.poses,
                 self.stats.markers,
                 ", ".join(f"{k} {v}" for k, v in self.stats.refused.items()) or "none", self.core.points_left_out,
                 self.rejects.summary())
        return self.stats

    def _source(self) -> str:
        if self.config.input == "ros2":
            return f"ROS 2 PoseArray on {self.config.ros2_topic} (domain {self.config.ros2_domain_id})"
        return f"{self.keys.keypoints}" + (f" (playing {self.config.from_file})" if self.config.from_file else "")

    def _inputs(self, session: Any) -> list[Any]:
        """Subscribe to the configured input; returns what to close."""
        cfg = self.config
        if cfg.input == "zenoh":
            sub = subscribe(session, self.keys.keypoints, HumanKeypoints, lambda msg: self.backlog.put((msg, True)),
                            self.rejects, Receipt(Expectations(clock="realtime")))
            return [sub.undeclare]
        from services.ros2.core import KEYPOINTS_TYPE, Ros2Config, Ros2Mapping
        from services.ros2.node import Ros2Node

        mapping = Ros2Mapping(Ros2Config(domain_id=cfg.ros2_domain_id))
        names = list(cfg.ros2_points) or self.core.layout.native_order  # the sensor's own: COCO's 17 by index
        node = Ros2Node(session, cfg.ros2_domain_id, "/", NODE_NAME, mapping.hashes, self.rejects)
        node.subscription(cfg.ros2_topic, KEYPOINTS_TYPE, lambda payload: self._on_pose_array(mapping, names, payload))
        log.info("tracker: ROS 2 node /%s takes %s, poses in the order %s", NODE_NAME, cfg.ros2_topic, names)
        return [node.close]

    def _wait_until(self, when: float, stop: threading.Event) -> bool:
        """Wait until monotonic time ``when``, ending a reach across a silence meanwhile; whether stop was set.

        A recording's missing frames are a silence like a live sensor's: :meth:`check_silence` runs as in the
        live loop, so the reach ends within ``max_gap_s`` of its last frame, not at the next frame.
        """
        poll = min(0.1, self.config.tracker.max_gap_s / 3)
        while (delay := when - time.monotonic()) > 0:
            if stop.wait(min(delay, poll)):
                return True
            self.check_silence()
        return stop.is_set()

    def _play(self, playback: Playback, stop: threading.Event) -> None:
        """Play the recording on the keypoints key in real time, as the ``sensor`` role."""
        zcfg = dataclasses.replace(self.zenoh_config, role=SENSOR, listen=[],
                                   mode="client" if self.zenoh_config.mode == "client" else "peer")
        with open_session(zcfg, stop, "tracker player") as session:
            pub: TypedPublisher[HumanKeypoints] = TypedPublisher(session, self.keys.keypoints, block=True)
            log.info("tracker: playing %s: %d demonstrations, %.1f s a pass%s", self.config.from_file,
                     len(playback.demos), playback.duration_s(), " (looping)" if playback.config.loop else "")
            deadline = time.monotonic() + 10.0  # the first frames go once the tracker's subscription is routed here
            while not pub.matched() and time.monotonic() < deadline and not stop.wait(0.05):
                pass
            start, wall = time.monotonic(), time.time()
            for frame in playback.frames():
                if self._wait_until(start + frame.t, stop):
                    break
                try:  # stamped when due, not when sent: frames sent late in a burst are still 1/rate apart, not a jump
                    pub.put(HumanKeypoints(stamp=wall + frame.t, tick=-1, frame=frame.frame,
                                           frame_id=self.config.tracker.frame_id, names=playback.names,
                                           positions=frame.positions))
                except ProtocolError as exc:  # the recording holds a frame the contract refuses: say so, go on
                    log.warning("tracker: recording frame %d not sent: %s", frame.frame, exc)
                    continue
                self.stats.played += 1
            log.info("tracker: played %d frames", self.stats.played)
