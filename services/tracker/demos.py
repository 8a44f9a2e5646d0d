"""Smoothed frames -> the demonstrations the predictor reads: the reaches, and the person seen at rest.

The predictor recognises demonstrations as the recorder gave them: a ``DemoMarker`` start, the poses (index 0, 1,
... from the start; ``demo_id`` one per demonstration), an end. A live person gives none, so the tracker makes them:

- **reaches**, from the reach rule (:mod:`.reach`): a start (its first pose ``pre_s`` before the threshold was
  crossed), the poses, and an ``end`` when the hand has come to rest, or ``lost`` when the tracker loses the person
  mid-reach (a gap, another body, the tracker stopping: where the person went is unknown);
- **the person at rest**: once per track (the first, and each after a loss), when the rule has learnt where the hand
  rests, a short demonstration of the person standing still (class name :data:`~shared.protocol.AT_REST`, the last
  ``pre_s`` of frames, at most 10 poses), ended at once. The predictor predicts from it where the person may reach
  (every class's volume by its posterior, as at the start of any reach), and the executor, which does not move the
  robot without a prediction, need not wait for the first reach; after a lost reach it holds until the person is
  seen again, at rest or reaching (before, only a reach let it go on).

Between demonstrations nothing is published.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from shared.feature_sets import HERAKLES_NAMES
from shared.human import HumanModel
from shared.protocol import AT_REST, DemoMarker, HumanPose, Message

from .reach import ReachDetector, ReachRule, body_wrist

__all__ = ["Demonstrations", "REST_POSES", "LIVE_CLASS", "reach_messages", "reach_poses"]

_YAW = HERAKLES_NAMES.index("pelvis_yaw")

LIVE_CLASS = "live"
"""The ``class_name`` of a live person's reaches (the class is what the predictor recognises)."""

REST_POSES = 10
"""At most this many poses in a demonstration of the person at rest: enough for the predictor's novelty test (judged
from the third frame) and its median window (10), no more than a reach's own first poses before it moves."""


class Demonstrations:
    """Feeds on smoothed frames; gives the markers and poses of the reaches and of the person seen at rest.

    Args:
        rule: The reach rule's thresholds.
        model: The human model (the wrist's position from the features).
        announce_rest: Publish the person seen at rest once per track.

    Attributes:
        reaches: Reaches started; ``lost``: of them, lost mid-reach. ``rests``: demonstrations of the person at rest.
        demo_id: The last demonstration's number (-1 before the first).
    """

    def __init__(self, rule: ReachRule, model: HumanModel, announce_rest: bool = True) -> None:
        self.rule, self.model, self.announce_rest = rule, model, announce_rest
        self.reach = ReachDetector(rule)
        self.reaches = self.lost = self.rests = 0
        self.demo_id = -1
        self._index = 0
        self._recent: deque[tuple[float, np.ndarray]] = deque()  # smoothed frames of the last pre_s (pre-trigger)
        self._ended_at = -math.inf                              # the last reach's end stamp
        self._rest_said = False                                  # the person at rest published for this track

    def frame(self, t: float, f: np.ndarray) -> list[Message]:
        """A smoothed frame (features ``(12,)`` at ``t`` s) through the reach rule: the markers and poses it gives."""
        self._recent.append((t, f))
        while self._recent and self._recent[0][0] < t - self.rule.pre_s - 1e-9:
            self._recent.popleft()
        event = self.reach.update(body_wrist(self.model.joint_positions(np.asarray(f, dtype=np.float64))), t)
        msgs: list[Message] = []
        if self.announce_rest and not self._rest_said and self.reach.settled:
            self._rest_said = True  # a reach starting on this very frame is the person seen: no rest of a moving hand
            msgs = self._at_rest() if event is None and not self.reach.active else []
        if event is not None and event.event == "start":
            self.reaches += 1
            first = [(s, g) for s, g in self._recent if s >= event.stamp - 1e-9 and s > self._ended_at] or [(t, f)]
            msgs += [self._start(first[0][0], LIVE_CLASS)]
            return msgs + [self._pose(s, g) for s, g in first]
        if not self.reach.active and event is None:
            return msgs
        msgs.append(self._pose(t, f))
        if event is not None and event.event == "end":
            self._ended_at = t  # no pose of the ended reach is a pose of the next one
            return msgs + [self._marker(t, "end", LIVE_CLASS)]
        return msgs

    def lose(self, last: float) -> list[Message]:
        """The track is lost (a gap, another body, the tracker stopping): a reach under way is ``lost`` at ``last``.

        Everything about the track is forgotten: the next frames start a new one (its rest learnt, and said, again).
        """
        msgs = [self._marker(last, "lost", LIVE_CLASS)] if self.reach.active else []
        self.lost += bool(msgs)
        self.reach.reset()
        self._recent.clear()
        self._ended_at = -math.inf  # a sensor restarted, or a clock stepped back: its frames may precede the last end
        self._rest_said = False
        return msgs

    def _at_rest(self) -> list[Message]:
        """The person standing still, as a demonstration of its own (class :data:`AT_REST`), started and ended."""
        self.rests += 1
        frames = list(self._recent)[-REST_POSES:]
        self._ended_at = frames[-1][0]  # the next reach's first poses come after these (its stamps never go back)
        return [self._start(frames[0][0], AT_REST), *(self._pose(s, g) for s, g in frames),
                self._marker(frames[-1][0], "end", AT_REST)]

    def _start(self, t: float, class_name: str) -> DemoMarker:
        self.demo_id += 1
        self._index = 0
        return DemoMarker(stamp=t, tick=-1, demo_id=self.demo_id, event="start", true_class=-1,
                          class_name=class_name, n_samples=0)

    def _pose(self, t: float, f: np.ndarray) -> HumanPose:
        features = np.asarray(f, dtype=np.float64).copy()
        # the fit follows the yaw continuously from its first guess: a track begun on the other side of +-pi, or a
        # person who turned round, published it 2 pi off the libraries' convention (recognised 10 of 40 reaches)
        features[_YAW] = (features[_YAW] + math.pi) % (2 * math.pi) - math.pi
        pose = HumanPose(stamp=t, tick=-1, tick_last=True, demo_id=self.demo_id, index=self._index,
                         features=features)
        self._index += 1
        return pose

    def _marker(self, t: float, event: str, class_name: str) -> DemoMarker:
        return DemoMarker(stamp=t, tick=-1, demo_id=self.demo_id, event=event, true_class=-1, class_name=class_name,
                          n_samples=self._index)


def reach_messages(messages: list[Message], rest: set[int]) -> list[Message]:
    """The markers and poses of ``messages`` that are a reach's, not the person's at rest.

    ``rest``: the ``demo_id`` of every demonstration of the person at rest seen so far; the start markers among
    ``messages`` are added to it (a demonstration's start comes before its poses).
    """
    rest.update(m.demo_id for m in messages if isinstance(m, DemoMarker) and m.class_name == AT_REST)
    return [m for m in messages if isinstance(m, HumanPose | DemoMarker) and m.demo_id not in rest]


def reach_poses(messages: list[Message], rest: set[int]) -> list[HumanPose]:
    """The poses of :func:`reach_messages`."""
    return [m for m in reach_messages(messages, rest) if isinstance(m, HumanPose)]
