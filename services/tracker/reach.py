"""When a reach begins and ends: the rule that stands in for the recorder's demonstration markers.

A live person gives no markers, and the predictor recognises a motion from its start. The rule: the right
wrist, in the body's own frame (relative to the pelvis, turned by its yaw, so that walking or turning is not a
reach), has a rest position - its mean over the first ``rest_s`` (no reach can start before), then its running
mean while no reach is under way. A reach **starts** when the
wrist is more than ``start_m`` from rest; its first pose is the one ``pre_s`` before that moment (the motion
began before the threshold was crossed: the library's demonstrations start at rest). It **ends** when the
wrist has stayed within ``end_m`` of a still position for ``end_s`` (the hand came to rest: at the goal or
back home), or after ``max_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ReachRule", "ReachDetector", "ReachEvent"]


@dataclass(frozen=True)
class ReachRule:
    """The rule's thresholds (the tracker's config holds them)."""

    start_m: float = 0.10
    end_m: float = 0.03
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
        self._still_since: float | None = None
        self._still_at: np.ndarray | None = None

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
            if np.linalg.norm(w - self._rest) > r.start_m:
                self.active, self._start_t = True, t
                self._still_since, self._still_at = None, None
                return ReachEvent("start", t - r.pre_s)
            a = min(1.0, dt / r.rest_s) if r.rest_s > 0 else 1.0  # the rest position follows a still hand
            self._rest = self._rest + a * (w - self._rest)
            return None
        if self._still_at is None or np.linalg.norm(w - self._still_at) > r.end_m:
            self._still_at, self._still_since = w.copy(), t
        assert self._still_since is not None
        if t - self._still_since >= r.end_s or t - self._start_t >= r.max_s:
            self.active = False
            self._rest = w.copy()  # where the hand came to rest is the new rest position
            return ReachEvent("end", t)
        return None
