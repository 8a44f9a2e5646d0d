"""When a reach begins and ends: the rule that stands in for the recorder's demonstration markers.

A live person gives no markers, and the predictor recognises a motion from its start. The rule: the right
wrist, in the body's own frame (relative to the pelvis, turned by the shoulder line's yaw, so that walking or
turning is not a reach), has a rest position - its mean over the first ``rest_s`` (no reach can start before),
then its running mean while no reach is under way. A reach **starts** when the wrist is more than ``start_m`` from
rest; its first pose is the one ``pre_s`` before that moment (the motion began before the threshold was crossed:
the library's demonstrations start at rest). It **ends** when the hand
has come to rest (at the goal or back home): the wrist's positions over the last ``end_s`` lie within ``end_m``
of their mean, as a root mean square - not every frame within it, because a sensor's centimetre noise, which the
smoothing lets through at speed, kept a still hand "moving" (with 1 or 2 cm of noise per axis a reach never ended
when the rule asked every frame to stay within 3 cm of one place), and not the drift of the mean alone, which a
hand going out and back within the window does not show (the paper's motions ended mid-reach) - or after
``max_s``. After such a forced end the hand may still move, so its rest position is learnt again (over
``rest_s``, no reach starting meanwhile) rather than taken from a moving hand, which started a new reach at
once with the ended one's last poses.

A reach starts **from rest**, as the library's demonstrations do. One that ended with the hand away from its rest
position (at the goal) leaves the rule *returning*: the hand going back is no reach, and the next one can start
once the wrist is within ``start_m`` of its rest again, or has left the goal and come to rest elsewhere (that is
its rest position then). Before, the goal became the rest position and the way back was published as a reach of
its own, recognised as some class with full confidence (a review's live run: ``near_centre p=1.00`` for a
return). If the hand stays at the goal for ``max_s``, its rest position is learnt again where it is. A motion from
one goal straight to another is no reach either (it does not start at rest, and the library has none like it).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES

from .filters import smooth_sequence

if TYPE_CHECKING:
    from shared.library import Demonstration

    from .core import TrackerConfig

__all__ = ["ReachRule", "ReachDetector", "ReachEvent", "body_wrist", "spread", "first_start", "recorded_start",
           "from_tracker_start"]

_WRIST, _PELVIS = POINT_NAMES.index("r_wrist"), POINT_NAMES.index("pelvis")
_SHOULDERS = POINT_NAMES.index("r_shoulder"), POINT_NAMES.index("l_shoulder")


def body_wrist(joints: np.ndarray) -> np.ndarray:
    """The right wrist relative to the pelvis, turned by the shoulder line's yaw (the body's frame): ``(3,)``.

    Args:
        joints: ``(J, 3)`` the human model's joint positions (``shared.keypoints.fit.POINT_NAMES`` order).

    The yaw is the shoulder line's, from the fitted joint positions, not the pelvis yaw feature: the fit splits a
    turn between the pelvis yaw and the torso twist, which under 2 cm of sensor noise swung the wrist 14.5 cm
    (p99) in a frame turned by the yaw feature, against 3.1 cm in this one (a still person, 10 s).
    """
    across = joints[_SHOULDERS[1]] - joints[_SHOULDERS[0]]  # right to left shoulder: the body's +y
    yaw = float(np.arctan2(across[1], across[0])) - 0.5 * np.pi
    c, s = np.cos(yaw), np.sin(yaw)
    v = joints[_WRIST] - joints[_PELVIS]
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


@dataclass(frozen=True)
class ReachRule:
    """The rule's thresholds (the tracker's config holds them)."""

    start_m: float = 0.10
    end_m: float = 0.02
    end_s: float = 0.5
    pre_s: float = 0.3
    rest_s: float = 1.0
    max_s: float = 10.0


@dataclass(frozen=True)
class ReachEvent:
    """``"start"`` (with the stamp of the reach's first pose) or ``"end"`` (``forced``: by ``max_s``, hand moving)."""

    event: str
    stamp: float
    forced: bool = False


class ReachDetector:
    """Feeds on the wrist's body-frame position per frame; says when a reach starts and ends.

    Args:
        rule: The thresholds.
    """

    def __init__(self, rule: ReachRule) -> None:
        self.rule = rule
        self.reset()

    def reset(self) -> None:
        """Forget the rest position and any reach under way (after a long gap)."""
        self.active = False
        self._rest: np.ndarray | None = None
        self._t: float | None = None
        self._since: float | None = None  # the first frame after a reset: the rest position is learnt from then
        self._n = 0
        self._start_t = 0.0
        self._window: deque[tuple[float, np.ndarray]] = deque()  # the wrist over the last end_s of the reach
        self._away: float | None = None  # when a reach ended with the hand away from rest (returning until back)
        self._goal = np.zeros(3)  # where that reach ended
        self._left_goal = False  # the hand has left it since

    @property
    def settled(self) -> bool:
        """Whether the hand's rest position is known: learnt over ``rest_s`` since the track began (or was relearnt)."""
        return (self._since is not None and self._rest is not None and self._t is not None
                and self._t - self._since >= self.rule.rest_s)

    def update(self, wrist: np.ndarray, t: float) -> ReachEvent | None:
        """The event at this frame, if any (``wrist``: ``(3,)`` body-frame position, m; ``t``: s)."""
        r = self.rule
        w = np.asarray(wrist, dtype=np.float64)
        dt = 0.0 if self._t is None else max(0.0, t - self._t)
        self._t = t
        if not self.active:
            if self._since is None or self._rest is None:
                self._since, self._rest, self._n = t, w.copy(), 1
                return None
            if t - self._since < r.rest_s:  # learning where the hand rests: the mean of these frames
                self._n += 1
                self._rest = self._rest + (w - self._rest) / self._n
                return None
            if self._away is not None:  # the hand on its way back from the last reach's goal: no reach
                self._returning(w, t)
                return None
            if np.linalg.norm(w - self._rest) > r.start_m:
                self.active, self._start_t = True, t
                self._window.clear()
                return ReachEvent("start", t - r.pre_s)
            a = min(1.0, dt / r.rest_s) if r.rest_s > 0 else 1.0  # the rest position follows a still hand
            self._rest = self._rest + a * (w - self._rest)
            return None
        self._window.append((t, w))
        while len(self._window) > 1 and t - self._window[1][0] >= r.end_s:  # the oldest kept: end_s ago or more
            self._window.popleft()
        still = self._still()
        if still or t - self._start_t >= r.max_s:
            self.active = False
            if still:
                half = self._window[-1][0] - 0.5 * r.end_s  # where the hand came to rest (the window's recent half)
                stop = np.mean([p for s, p in self._window if s >= half], axis=0)
                if np.linalg.norm(stop - self._rest) > r.start_m:
                    self._away, self._goal, self._left_goal = t, stop, False  # at the goal: the way back is no reach
                    self._window.clear()
                else:
                    self._rest = stop  # back home (a reach out and back within the window)
            else:  # ended by max_s while the hand still moves: where it rests is learnt again, over rest_s
                self._since = self._rest = None
            return ReachEvent("end", t, forced=not still)
        return None

    def _returning(self, w: np.ndarray, t: float) -> None:
        """The hand after a reach that ended at its goal: back at rest, or at rest somewhere else, ends the return.

        Put down a little off its old rest (12 cm, say), the hand would have stayed "returning" for ``max_s`` and
        every reach meanwhile missed: once it has left the goal and been still for ``end_s``, where it is becomes
        the rest position.
        """
        r = self.rule
        self._window.append((t, w))
        while len(self._window) > 1 and t - self._window[1][0] >= r.end_s:
            self._window.popleft()
        self._left_goal = self._left_goal or bool(np.linalg.norm(w - self._goal) > r.start_m)
        if np.linalg.norm(w - self._rest) <= r.start_m:
            self._away = None  # back at rest: the next reach may start
        elif self._left_goal and self._still():
            self._rest, self._away = np.mean([p for _, p in self._window], axis=0), None
        elif t - self._away >= r.max_s:  # it stays at the goal: where it rests is learnt again, from here
            self._away, self._since, self._rest, self._n = None, t, w.copy(), 1
        if self._away is None:
            self._window.clear()

    def _still(self) -> bool:
        """Whether the window spans ``end_s`` and its wrist positions lie within ``end_m`` (rms) of their mean."""
        r = self.rule
        if self._window[-1][0] - self._window[0][0] < r.end_s - 1e-9 or len(self._window) < 4:
            return False
        return spread(np.array([w for _, w in self._window])) < r.end_m


def spread(points: np.ndarray) -> float:
    """The rms distance of positions ``(N, ..., 3)`` from their mean over the ``N`` frames (m): how still they are."""
    return float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=-1))))


def first_start(wrists: np.ndarray, rate_hz: float, rule: ReachRule) -> int | None:
    """The sample of the first reach's first pose, as the rule starts it on a motion that begins at rest.

    The first position is held for ``rest_s`` before the motion (the rule learns the rest position over it, and no
    reach starts meanwhile), as for a person standing still before reaching; a first pose within ``pre_s`` of the
    motion's start is its sample 0.

    Args:
        wrists: ``(T, 3)`` the wrist's body-frame positions (:func:`body_wrist`), one per sample at ``rate_hz``.
        rate_hz: Samples per second.
        rule: The thresholds.

    Returns:
        The sample in ``0 .. T - 1``, or None where no reach starts (the wrist never goes ``start_m`` from rest).
    """
    held = int(np.ceil(rule.rest_s * rate_hz)) + 1
    det = ReachDetector(rule)
    for k, w in enumerate(np.concatenate([np.repeat(wrists[:1], held, axis=0), wrists])):
        event = det.update(w, k / rate_hz)
        if event is not None:  # not under way: a start
            # the first pose is the first frame at or after the start's stamp (services.tracker.demos)
            return min(len(wrists) - 1, max(0, int(np.ceil(event.stamp * rate_hz - 1e-6)) - held))
    return None


def recorded_start(features: np.ndarray, config: TrackerConfig, model: HumanModel | None = None) -> int:
    """Where the tracker would start a recorded demonstration's reach: its sample there (0 where it starts none).

    The features are smoothed with the tracker's One-Euro filter, the wrist placed by the human model, and the rule
    run (:func:`first_start`) with ``config``'s thresholds at its ``pose_rate_hz`` (the library's clock): what the
    tracker does with a person's keypoints, less the sensor and the fit.

    Args:
        features: ``(T, 12)`` the paper's posture features at ``config.pose_rate_hz``, starting at rest.
        config: The tracker's options (:class:`services.tracker.core.TrackerConfig`).
        model: The human model (default: ``HumanModel()``).
    """
    model = model or HumanModel()
    f = smooth_sequence(features, config.pose_rate_hz, config.min_cutoff_hz, config.beta)
    wrists = np.array([body_wrist(j) for j in model.joint_positions(f)])
    start = first_start(wrists, config.pose_rate_hz, config.rule)
    return 0 if start is None else start


def from_tracker_start(demos: list[Demonstration], config: TrackerConfig | None = None) -> list[Demonstration]:
    """Each demonstration cut where the tracker would start its reach (:func:`recorded_start`), indexed from there.

    The cut of ``foresight train --time-from tracker`` (its model's time starts at the tracker's first pose of a
    reach) and of ``foresight eval recognition --through-tracker --time-from tracker``: one rule for both.

    Args:
        demos: The demonstrations, their features at the tracker's ``pose_rate_hz``.
        config: The tracker's options (default: ``TrackerConfig()``, the defaults a person's tracker runs with).
    """
    from dataclasses import replace

    from .core import TrackerConfig as Defaults  # the tracker's core imports this module

    config = config or Defaults()
    return [replace(d, features=d.features[recorded_start(d.features, config):]) for d in demos]
