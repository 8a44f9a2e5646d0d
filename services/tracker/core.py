"""The tracker's core: a person's body keypoints in, the paper's posture features and reach markers out.

No Zenoh here. Per keypoint frame (``HumanKeypoints``: names, positions (K, 3) in the sensor's frame, a stamp):

0. a frame in another coordinate frame than ``frame_id``, or naming a point its layout does not have, is refused;
   one stamped less than ``1 / max_fit_hz`` after the last accepted frame is skipped (not fitted, counted in
   :attr:`TrackerCore.skipped`): the poses come at the library's 30 a second, and fitting every frame of a 120 Hz
   sensor (5-13 ms each) fell seconds behind it;
1. the layout's table maps the sensor's points to the human model's (:mod:`shared.keypoints.layouts`); a frame
   without a required point is refused;
2. the human model is fitted, warm-started from the last accepted frame (:class:`shared.keypoints.fit.KeypointFit`);
3. a frame not stamped after the last accepted one is refused (the jump check and the smoothing need time to
   pass; frame numbers are checked on receipt, stamps here). A frame whose fit residual (rms) exceeds
   ``max_residual_m``, or one of whose fitted joints moved faster
   than ``max_speed_mps`` since the last accepted frame, is refused (a swapped or wild point: sensors do
   that). The check is on joint positions, not angles: the fit may split a turn between the pelvis yaw and
   the torso twist differently from one frame to the next (docs/keypoints.md) without any joint moving;
4. the features are smoothed by a One-Euro filter (:mod:`.filters`);
5. a gap (dropped or refused frames) up to ``max_gap_s`` is bridged: the missing frames, at the sensor's
   period (:mod:`.rate`: a burst's intervals left out, so it never makes the bridge invent frames between the
   next regular ones), are interpolated between the frames on either side; a longer gap loses the person (a
   ``lost`` marker of the reach under way, or of the ended demonstration that showed them: their whereabouts
   unknown) and starts afresh;
5b. a sensor whose rate is more than 10 % off the motion library's (``pose_rate_hz``, 30) has its frames resampled
   to that rate (:mod:`.resample`): the predictor reads a pose's index as its time;
6. the reach rule (:mod:`.reach`) says when a reach starts and ends, and :mod:`.demos` makes the demonstrations
   the predictor reads: ``DemoMarker`` start and end, the poses in between as ``HumanPose`` (index 0, 1, ... from
   the start; ``demo_id`` one per demonstration), and the person seen at rest (a short demonstration
   of its own, class ``AT_REST``). Between them nothing is published.

Every refused frame is counted by reason (:attr:`TrackerCore.refused`) and named in :attr:`TrackerOutput.refused`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shared.config import ConfigError, opt
from shared.feature_sets import HERAKLES_NAMES
from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES, REQUIRED, KeypointFit
from shared.keypoints.layouts import LAYOUTS, load_layout
from shared.protocol import HumanKeypoints, Message

from .checks import Upright, fit_without_outliers, furthest_point, missing_points, torso_tilt_deg
from .demos import Demonstrations
from .filters import OneEuroFilter
from .rate import MIN_PERIOD_S, FrameRate
from .reach import ReachRule
from .resample import PoseClock

__all__ = ["TrackerConfig", "TrackerCore", "TrackerOutput", "REASONS", "MIN_PERIOD_S", "JUMP_CONFIRM",
           "LIBRARY_RATE_HZ"]

REASONS = ("frame", "names", "missing", "upright", "order", "leap", "range", "residual", "jump")
"""Why a frame is refused: another coordinate frame, a point the layout does not have, a required point missing, a
torso leaning too far from the vertical (keypoints whose up is not z: :mod:`services.tracker.checks`), a stamp not
after the last accepted frame's, a stamp a long gap after it that the next frame has not confirmed yet, a pelvis
outside the range the fit covers (so the fit cannot reach the points), a fit too far from the points, an implausible
jump."""

LIBRARY_RATE_HZ = 30.0
"""The rate of the motion libraries (the paper's recordings and the replayer's default): the predictor's time feature
is a pose's index, so the poses of a sensor far from this rate are resampled to it (:mod:`.resample`,
docs/keypoints.md)."""

JUMP_CONFIRM = 3
"""Frames in a row of the body a jump was refused to (each following the one before) that make it a new track:
the reach under way ends and the new body is tracked afresh. Before, the speed over the growing time since the last
accepted frame fell under the limit after 0.2-0.3 s and the new body was glided to as the same person."""


@dataclass
class TrackerConfig:
    """The tracker core's options (``[tracker]``)."""

    layout: str = opt("foresight", choices=LAYOUTS, help="the sensor's skeleton layout (docs/keypoints.md)")
    frame_id: str = opt("recorder", help="the coordinate frame the keypoints must be in (the motion library's); a "
                        "frame in another is refused")
    max_residual_m: float = opt(0.08, help="refuse a frame whose fit leaves its points further than this (rms, m)")
    max_speed_mps: float = opt(6.0, help="refuse a frame one of whose fitted joints moved faster than this since the "
                               "last accepted frame (m/s; a fast reach's hand: 2-4)")
    max_gap_s: float = opt(0.3, help="bridge a gap in the frames up to this long (interpolated); a longer one "
                           "loses the person (the reach under way, or the demonstration that showed them)")
    min_cutoff_hz: float = opt(1.5, help="One-Euro smoothing: the cutoff on a still person (Hz)")
    beta: float = opt(0.3, help="One-Euro smoothing: how fast the cutoff rises with speed")
    start_m: float = opt(0.10, help="a reach starts when the right wrist is this far from its rest position (m)")
    end_m: float = opt(0.02, help="a reach ends when the wrist's positions lie within this (m, rms) of their mean ...")
    end_s: float = opt(1.0, help="... over the last end_s seconds (the hand came to rest)")
    pre_s: float = opt(0.3, help="a reach's first pose is this long before the start threshold was crossed (s)")
    rest_s: float = opt(1.0, help="the hand's rest position is learnt over this long after a (re)start; no reach "
                        "starts before (s)")
    announce_rest: bool = opt(True, help="once the rest position is learnt and the body is still (at a track's "
                              "start, after a loss, and for an executor that appears), publish the person at rest "
                              "as a short demonstration (class 'rest'): the robot moves around its prediction "
                              "instead of waiting for the first reach")
    max_reach_s: float = opt(10.0, help="a reach ends after this long in any case (s)")
    moved_m: float = opt(0.10, help="after a demonstration's end, the person has moved away (its prediction no longer "
                         "says where they are: 'lost', the robot holds until they are seen again) once their pelvis "
                         "or a shoulder is this far from every place the demonstration showed it in (m; as far as a "
                         "hand leaves its rest to start a reach)")
    pose_rate_hz: float = opt(LIBRARY_RATE_HZ, help="the motion library's pose rate: a sensor more than 10 % off it "
                              "has its poses resampled to it (a pose's index is its time for the predictor)")
    max_fit_hz: float = opt(2 * LIBRARY_RATE_HZ, help="fit at most this many frames a second: a frame stamped sooner "
                            "after the last one taken is skipped (a 120 Hz sensor is fitted at 60; the poses come "
                            "at pose_rate_hz)")

    def validate(self) -> None:
        """Check ranges; raises ConfigError naming the option."""
        for name in ("max_residual_m", "max_speed_mps", "max_gap_s", "min_cutoff_hz", "start_m",
                     "end_m", "end_s", "rest_s", "max_reach_s", "moved_m", "pose_rate_hz", "max_fit_hz"):
            v = getattr(self, name)
            if not (v > 0 and math.isfinite(v)):
                raise ConfigError(f"tracker.{name}: must be a finite number > 0, got {v}")
        if not (self.beta >= 0 and math.isfinite(self.beta)):
            raise ConfigError(f"tracker.beta: must be a finite number >= 0, got {self.beta}")
        if 1 / self.max_fit_hz >= self.max_gap_s:  # else every frame fitted comes a gap after the last one taken
            raise ConfigError(f"tracker.max_fit_hz: {self.max_fit_hz:g} fits a frame every {1 / self.max_fit_hz:.3g} s "
                              f"at most, not within max_gap_s = {self.max_gap_s:g} s: every frame would be a gap")
        if not (0 <= self.pre_s <= self.max_reach_s):  # inf: the buffer of recent poses never shrank
            raise ConfigError(f"tracker.pre_s: must be in [0, max_reach_s = {self.max_reach_s:g}] s, got {self.pre_s}")

    @property
    def rule(self) -> ReachRule:
        """The reach rule's thresholds."""
        return ReachRule(self.start_m, self.end_m, self.end_s, self.pre_s, self.rest_s, self.max_reach_s)


@dataclass
class TrackerOutput:
    """What one frame gave: messages to publish, and why it was refused (None: accepted)."""

    messages: list[Message] = field(default_factory=list)
    refused: str | None = None
    note: str | None = None  # once per track: something the user should know (the sensor's frames resampled)


class TrackerCore:
    """Keypoint frames -> ``HumanPose`` and ``DemoMarker`` messages (see the module docstring).

    Args:
        config: Thresholds, layout, smoothing.
        model: The human model (default: ``shared.human.HumanModel()``).

    Attributes:
        refused: Frames refused per reason (:data:`REASONS`).
        accepted: Frames accepted.
        skipped: Frames not fitted: stamped under ``1 / max_fit_hz`` after the last accepted one.
        unfitted: Frames not fitted to catch up with a backlog (``fit`` False).
        bridged: Poses interpolated across gaps and at frames left unfitted to catch up.
        demos: The demonstrations made of the smoothed frames (:class:`~services.tracker.demos.Demonstrations`:
            ``reaches``, ``lost``, ``rests``).
        points_left_out: Optional points left out of accepted frames' fits, far off them
            (:func:`~services.tracker.checks.fit_without_outliers`).
    """

    def __init__(self, config: TrackerConfig | None = None, model: HumanModel | None = None) -> None:
        self.config = config or TrackerConfig()
        self.config.validate()
        self.model = model or HumanModel()
        self.layout = load_layout(self.config.layout)
        self.fit = KeypointFit(model=self.model)
        self.filter = OneEuroFilter(self.config.min_cutoff_hz, self.config.beta)
        self.demos = Demonstrations(self.config.rule, self.model, self.config.announce_rest, self.config.moved_m)
        self.refused = dict.fromkeys(REASONS, 0)
        self.accepted = self.skipped = self.unfitted = self.bridged = self.points_left_out = 0
        self.upright = Upright()                                 # whether this track's keypoints have z up
        self._required = {p: list(POINT_NAMES).index(p) for p in REQUIRED}
        self._raw: tuple[float, np.ndarray] | None = None      # the last accepted fit (stamp, features)
        self._joints: np.ndarray | None = None                  # its joint positions (J, 3), for the jump check
        self._out: tuple[float, np.ndarray] | None = None      # the last smoothed frame
        self._frame_no: int | None = None                       # the last accepted frame's number (if given)
        self._leap: float | None = None                         # a refused frame's stamp a long gap after the last
        self._jump: tuple[float, np.ndarray, int] | None = None  # refused as a jump: (stamp, joints, frames in a row)
        self._rate_said = False                                  # the sensor's rate named for this track
        self.clock = PoseClock(self.config.pose_rate_hz)         # a pose per frame, or resampled to the library's
        self._unfitted: list[float] = []                         # stamps of frames left unfitted since the last taken
        self.rate = FrameRate()                                  # the accepted frames' rate: bridging, resampling
        self.sensor = FrameRate()                                # every frame's: what the sensor sends
        self._seen: float | None = None                          # the newest frame's stamp (any frame)

    def on_keypoints(self, msg: HumanKeypoints, numbered: bool = True, fit: bool = True) -> TrackerOutput:
        """One frame off the wire (decoded and checked): its coordinate frame and names, then :meth:`on_frame`.

        ``numbered``: ``msg.frame`` is the sensor's frame number (False: it only counts arrivals, as for ROS 2);
        ``fit``: False for a frame left unfitted to catch up with a backlog (:mod:`.catch_up`).
        """
        if msg.frame_id != self.config.frame_id:
            return self._refuse("frame", f"frame {msg.frame} is in {msg.frame_id!r}, the tracker takes "
                                f"{self.config.frame_id!r}")
        unknown = self.layout.unknown(list(msg.names))
        if unknown:
            return self._refuse("names", f"frame {msg.frame} names {', '.join(map(repr, unknown[:4]))}, not points of "
                                f"the layout {self.layout.name} (e.g. {', '.join(self.layout.source_names[:4])})")
        return self.on_frame(msg.stamp, list(msg.names), msg.positions, msg.frame if numbered else None, fit)

    def on_frame(self, stamp: float, names: list[str], positions: np.ndarray,
                 frame: int | None = None, fit: bool = True) -> TrackerOutput:
        """One keypoint frame: ``names`` (K) and ``positions`` ``(K, 3)`` m, NaN where missing; ``stamp`` s.

        ``frame``: the sensor's frame number, where it numbers them; a gap is then bridged with no more poses
        than the frames it dropped. ``fit`` False: only counted (the sensor's rate, :attr:`unfitted`).
        """
        if self._seen is not None and stamp > self._seen:
            self.sensor.add(stamp - self._seen)
        self._seen = stamp if self._seen is None else max(self._seen, stamp)
        if not fit:
            self.unfitted += 1
            self._unfitted.append(stamp)  # its pose is interpolated once the next frame is fitted (_bridge)
            return TrackerOutput()
        if self._raw is not None and 0 < stamp - self._raw[0] < 0.9 / self.config.max_fit_hz:
            self.skipped += 1  # (0.9: a 120 Hz sensor's every other frame is 1 / 60 s after the last, not 0.99 of it)
            self._frame_no = frame  # a frame skipped is no frame the sensor dropped (_bridge)
            return TrackerOutput()
        points = self.layout.to_model(list(names), np.asarray(positions, dtype=np.float64))
        observed = np.all(np.isfinite(points), axis=-1)
        missing = [p for p, j in self._required.items() if not observed[j]]
        if missing:
            return self._refuse("missing", f"required point(s) missing: "
                                f"{missing_points(self.layout, names, positions, missing)}")
        tilt, new_track = torso_tilt_deg(points), self._raw is None or stamp - self._raw[0] > self.config.max_gap_s
        if why := self.upright.problem(tilt, new_track):  # a camera's frame, a y-up one: the fit lays them down
            return self._refuse("upright", why)
        if self._raw is not None and not stamp > self._raw[0]:
            return self._refuse("order", f"stamp {stamp:.6f} s is not after the last accepted frame's "
                                f"({self._raw[0]:.6f} s)")
        if self._raw is not None and stamp - self._raw[0] > self.config.max_gap_s:
            # a long gap ends the reach under way: only when the next frame confirms it (one frame stamped ahead
            # of the others ended a reach and made every later frame's stamp "not after" its own)
            if self._leap is None or not stamp > self._leap:
                self._leap = stamp
                return self._refuse("leap", f"stamp {stamp:.6f} s is {stamp - self._raw[0]:.3f} s after the last "
                                    "accepted frame's: a gap, once the next frame's stamp comes after this one")
        self._leap = None
        prior = self._raw[1][None] if self._raw is not None and stamp - self._raw[0] <= self.config.max_gap_s else None
        res = self.fit.fit(np.nan_to_num(points)[None], observed[None], prior)
        res, dropped = fit_without_outliers(self.fit, points, observed, prior, res, self.config.max_residual_m)
        f, rms = res.features[0], float(res.rms_m[0])
        if rms > self.config.max_residual_m:
            outside = self._outside(points[self._required["pelvis"]])
            if outside:  # the fit stopped at its bound: its residual is the distance, not a bad fit
                return self._refuse("range", f"pelvis {outside}, outside the range the fit covers (the motion "
                                    "library's room: shared.feature_sets.HERAKLES_RANGES); the keypoints must be in "
                                    "the library's frame")
            limit = self.config.max_residual_m * 100
            return self._refuse("residual", f"fit residual {rms * 100:.1f} cm rms > {limit:g}; furthest: "
                                f"{furthest_point(self.layout, res)}")
        self.points_left_out += len(dropped)
        out = TrackerOutput()
        joints = self.model.joint_positions(f)
        if self._raw is not None and stamp - self._raw[0] > self.config.max_gap_s:
            out.messages += self._lost(self._raw[0])  # a long gap: the reach under way ends, everything starts afresh
        elif self._raw is not None:  # stamp > the last accepted one (refused above otherwise)
            dt = stamp - self._raw[0]
            moved = np.linalg.norm(joints - self._joints, axis=-1)
            j = int(np.argmax(moved))
            if self._jump is not None and self._follows(self._jump, joints, stamp, moved):
                # the body of the refused frames goes on (another person, a re-identified skeleton): never glide
                # over to it once the time since the last accepted frame has grown; JUMP_CONFIRM frames of it in a
                # row, and it is taken as a new track (the reach under way ends)
                n = self._jump[2] + 1
                self._jump = (stamp, joints, n)
                if n < JUMP_CONFIRM:
                    return self._refuse("jump", f"the body of the frame refused before goes on ({n} of "
                                        f"{JUMP_CONFIRM} frames): another person?")
                out.messages += self._lost(self._raw[0])
            elif moved[j] > max(self.config.max_speed_mps * dt, 2 * self.config.max_residual_m):
                self._jump = (stamp, joints, 1)
                return self._refuse("jump", f"{POINT_NAMES[j]} at {moved[j] / dt:.1f} m/s since the last frame")
            else:
                self.rate.add(dt)
        dropped = None if frame is None or self._frame_no is None or self._raw is None else frame - self._frame_no - 1
        self._raw, self._joints, self._frame_no, self._jump = (stamp, f), joints, frame, None
        self.accepted += 1
        self.upright.accepted(tilt, new_track)
        smooth = self.filter(f, stamp)
        taken_hz = self.rate.hz
        if self.clock.follow(taken_hz) and not self._rate_said:  # said once per track
            self._rate_said = True
            out.note = (f"the sensor sends {self._sent(taken_hz)}, the motion library's poses came at "
                        f"{self.clock.rate_hz:g}: its poses are resampled to {self.clock.rate_hz:g} a second (a "
                        "pose's index is its time for the predictor; docs/keypoints.md)")
        if self.clock.resampling:  # poses at the library's clock between the frames taken, unfitted ones or not
            self._unfitted.clear()
            for t, g in self.clock.poses(self._out, stamp, smooth):
                out.messages += self._frame(t, g)
        else:
            out.messages += self._bridge(stamp, smooth, dropped) + self._frame(stamp, smooth)
        self._out = (stamp, smooth)
        return out

    @property
    def tracking(self) -> bool:
        """Whether a frame was accepted since the start or the last loss (the core keeps a past to continue)."""
        return self._raw is not None

    def finish(self, recording_ended: bool = False) -> TrackerOutput:
        """The frames have stopped (the sensor quiet, the tracker stopping): the person is lost, the past forgotten.

        ``recording_ended``: the end of a recording played, where only a reach under way is lost (the person stands
        as last seen, as at a replayer's end).
        """
        return TrackerOutput(self._lost(self._raw[0], recording_ended) if self._raw is not None else [])

    # -- internals ---------------------------------------------------------------------------------

    def _sent(self, taken_hz: float) -> str:
        """The sensor's rate in words, and the rate taken where it differs (skipped or refused frames)."""
        sent_hz = self.sensor.hz or taken_hz
        if abs(sent_hz / taken_hz - 1.0) <= 0.1:
            return f"{taken_hz:.0f} frames a second"
        why = (f"max_fit_hz {self.config.max_fit_hz:g}" if self.skipped else "catching up with a backlog"
               if self.unfitted else "the others refused")
        return f"{sent_hz:.0f} frames a second ({taken_hz:.0f} a second taken: {why})"

    def _follows(self, refused: tuple[float, np.ndarray, int], joints: np.ndarray, stamp: float,
                 moved: np.ndarray) -> bool:
        """Whether ``joints`` ``(J, 3)`` at ``stamp`` continue the body of the frame last refused as a jump.

        And not the track's own body (``moved``: ``(J,)`` each joint's distance from the last accepted frame): a
        still person under noise (3 cm at 30 Hz, 2 cm at 60) had a frame refused, and the next ones, near both
        bodies, taken for another person's after three: the track started afresh (a review: 6 in 30 s at 60 Hz).
        And a body elsewhere as a whole: most of its joints (the median) further from the track's than the fit's
        tolerance allows over two frames; noise and a swapped point move a few joints (60 Hz, 3 cm: the frames
        taken for another person lay a median 5-9 cm from the track, a person beside it lies half a metre away).
        """
        last_t, last_joints, _ = refused
        dt = max(stamp - last_t, MIN_PERIOD_S)
        near = float(np.max(np.linalg.norm(joints - last_joints, axis=-1)))
        elsewhere = float(np.median(moved)) > 2 * self.config.max_residual_m
        return near / dt <= self.config.max_speed_mps and near < 0.5 * float(np.max(moved)) and elsewhere

    def _outside(self, pelvis: np.ndarray) -> str:
        """Where the observed pelvis ``(3,)`` lies beyond the fit's pelvis bounds, in words ('' if within)."""
        at = [HERAKLES_NAMES.index(f"pelvis_{axis}") for axis in "xyz"]
        words = [f"{axis} {v:.2f} m not in [{lo:g}, {hi:g}]"
                 for axis, v, lo, hi in zip("xyz", pelvis, self.fit.low[at], self.fit.high[at], strict=True)
                 if not lo <= v <= hi]
        return ", ".join(words)

    def _refuse(self, reason: str, why: str) -> TrackerOutput:
        self.refused[reason] += 1
        return TrackerOutput(refused=f"{reason}: {why}")

    def _lost(self, last: float, recording_ended: bool = False) -> list[Message]:
        """A gap too long, another body, or the tracker stopping: the person is lost, the past forgotten.

        Lost, not ended: where the person went is unknown; the marker of the reach under way, or of the ended
        demonstration that showed where they were, says so (``lost``, at the last frame; :meth:`Demonstrations.lose`).
        """
        msgs = self.demos.lose(last, recording_ended)
        self.filter.reset()
        self.rate.reset()  # the next frames may come from a sensor restarted at another rate
        self.sensor.reset()
        self._raw = self._out = self._joints = self._frame_no = self._leap = self._jump = None
        self._rate_said, self.upright.frames, self._unfitted = False, 0, []
        self.clock.reset()
        return msgs

    def _bridge(self, stamp: float, f: np.ndarray, dropped: int | None = None) -> list[Message]:
        """Frames interpolated between the last smoothed one and this, across frames left unfitted or a gap.

        Frames left unfitted to catch up (:mod:`.catch_up`): one at each of their stamps. A gap: the frames the
        sensor's numbers say it lost (``dropped``), else at the sensor's period while the last three intervals are each
        a whole number of periods (a backlog flushed after a stall, arrival-stamped a few ms apart, is no sensor's
        period; a frame lost in every 4th is): :meth:`.rate.FrameRate.missed`.
        """
        unfitted, self._unfitted = self._unfitted, []
        if self._out is not None and (between := sorted({t for t in unfitted if self._out[0] < t < stamp})):
            # frames left unfitted to catch up with a backlog: a pose at each, interpolated, so that the poses keep
            # the sensor's time (the kept frames alone made a 30 Hz reach's indices run at 23 a second)
            t0, f0 = self._out
            self.bridged += len(between)
            return [m for t in between for m in self._frame(t, f0 + (t - t0) / (stamp - t0) * (f - f0))]
        if self._out is None:
            return []
        t0, f0 = self._out
        n = self.rate.missed(stamp - t0, dropped)
        msgs: list[Message] = []
        for k in range(1, n + 1):
            a = k / (n + 1)
            msgs += self._frame(t0 + a * (stamp - t0), f0 + a * (f - f0))
            self.bridged += 1
        return msgs

    def _frame(self, t: float, f: np.ndarray) -> list[Message]:
        """A smoothed frame through the reach rule: the markers and poses it gives (:mod:`.demos`).

        It is on the library's clock once the sensor's rate is known (resampled, or a frame within 10 % of it); a 15 Hz
        sensor's rate is known after a second, as its person at rest was said, with the poses of its last 0.3 s at
        15 a second (the predictor reads their indices as time).
        """
        return self.demos.frame(t, f, on_clock=self.rate.hz is not None)
