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
once the wrist is within ``start_m`` of its rest again. Before, the goal became the rest position and the way back
was published as a reach of its own, recognised as some class with full confidence (a review's live run:
``near_centre p=1.00`` for a return). If the hand stays away for ``max_s``, its rest position is learnt again
where it is.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["ReachRule", "ReachDetector", "ReachEvent"]


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
    """``"start"`` (with the stamp of the reach's first pose) or ``"end"``."""

    event: str
    stamp: float


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
                if np.linalg.norm(w - self._rest) <= r.start_m:
                    self._away = None  # back at rest: the next reach may start
                elif t - self._away >= r.max_s:  # it stays away: where it rests is learnt again, from here
                    self._away, self._since, self._rest, self._n = None, t, w.copy(), 1
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
                    self._away = t  # at the goal: the way back is no reach
                else:
                    self._rest = stop  # back home (a reach out and back within the window)
            else:  # ended by max_s while the hand still moves: where it rests is learnt again, over rest_s
                self._since = self._rest = None
            return ReachEvent("end", t)
        return None

    def _still(self) -> bool:
        """Whether the window spans ``end_s`` and its wrist positions lie within ``end_m`` (rms) of their mean."""
        r = self.rule
        if self._window[-1][0] - self._window[0][0] < r.end_s - 1e-9 or len(self._window) < 4:
            return False
        p = np.array([w for _, w in self._window])
        return bool(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=-1))) < r.end_m)
