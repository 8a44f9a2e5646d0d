"""Smoothed frames -> the demonstrations the predictor reads: the reaches, and the person seen at rest.

The predictor recognises demonstrations as the recorder gave them: a ``DemoMarker`` start, the poses (index 0, 1,
... from the start; ``demo_id`` one per demonstration), an end. A live person gives none, so the tracker makes them:

- **reaches**, from the reach rule (:mod:`.reach`): a start (its first pose ``pre_s`` before the threshold was
  crossed), the poses, and an ``end`` when the hand has come to rest, or ``lost`` when the tracker loses the person
  mid-reach (a gap, another body, the tracker stopping: where the person went is unknown);
- **the person at rest**: once per track (the first, each after a loss, and for an executor that appears:
  :meth:`Demonstrations.say_again`), unless a reach says the person first, when the rule has learnt where the hand
  rests and the body stands still, a short demonstration of the person at rest (class name
  :data:`~shared.protocol.AT_REST`, the last ``pre_s`` of frames, at most 10 poses), ended at once. The predictor
  predicts from it where the person may reach (every class's volume by its posterior, as at the start of any
  reach), and the executor, which does not move the robot without a prediction, need not wait for the first reach.

After a demonstration's end the executor goes on with the prediction of its last pose: the person is taken to stay
where it showed them. So the tracker says when that no longer holds, with a ``lost`` marker of the ended
demonstration: the person out of view (a gap, another body, a live tracker stopping), or moved away from every
place the demonstration showed them in (pelvis or a shoulder more than ``moved_m`` from its path: walking off, or
turning round, with the arm still; a hand going back from a reach's goal retraces its path and is not). Before, the
robot went on around the old prediction. The executor then holds until the person is seen again, at rest (said
again, once the body is still) or reaching. The end of a recording played (``finish`` with ``recording_ended``) is
no loss: the person stands as last seen, as at a replayer's end.

Between demonstrations nothing else is published.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from shared.feature_sets import HERAKLES_NAMES
from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES
from shared.protocol import AT_REST, DemoMarker, HumanPose, Message

from .reach import ReachDetector, ReachRule, body_wrist, spread

__all__ = ["Demonstrations", "REST_POSES", "LIVE_CLASS", "reach_messages", "reach_poses"]

_YAW = HERAKLES_NAMES.index("pelvis_yaw")
_BODY = [POINT_NAMES.index(n) for n in ("pelvis", "r_shoulder", "l_shoulder")]
"""The points whose places say where the person is (not the arms: a reach moves them, and its rule watches them)."""

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
        announce_rest: Publish the person seen at rest (once per track, and again after a loss or for an executor).
        moved_m: The person has moved away once their pelvis or a shoulder is this far (m) from every place the
            last demonstration showed it in.

    Attributes:
        reaches: Reaches started; ``lost``: of them, lost mid-reach. ``rests``: demonstrations of the person at rest.
        unseen: Ended demonstrations lost (the person out of view, or moved away from where they showed them).
        demo_id: The last demonstration's number (-1 before the first).
    """

    def __init__(self, rule: ReachRule, model: HumanModel, announce_rest: bool = True, moved_m: float = 0.10) -> None:
        self.rule, self.model, self.announce_rest, self.moved_m = rule, model, announce_rest, moved_m
        self.reach = ReachDetector(rule)
        self.reaches = self.lost = self.rests = self.unseen = 0
        self.demo_id = -1
        self._index = 0
        self._class = LIVE_CLASS
        # smoothed frames of the last pre_s (pre-trigger): stamp, features, the body's points (3, 3)
        self._recent: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
        self._ended_at = -math.inf                              # the last reach's end stamp
        self._rest_said = False                                  # the person at rest published for this track
        self._body: deque[tuple[float, np.ndarray]] = deque()  # the body's points over the last end_s (is it still?)
        self._path: list[np.ndarray] = []                        # the body's points at each pose of the demonstration
        self._shown: np.ndarray | None = None  # (N, 3, 3): where the ended demonstration showed the body, until lost
        self._clock_at = -math.inf  # the first pose on the library's clock (inf: not yet)

    def frame(self, t: float, f: np.ndarray, on_clock: bool = True) -> list[Message]:
        """A smoothed frame (features ``(12,)`` at ``t`` s) through the reach rule: the markers and poses it gives.

        ``on_clock``: the frame is a pose on the library's clock (the sensor's rate known); the person at rest is said
        only with poses that all are.
        """
        if not on_clock:
            self._clock_at = math.inf
        elif self._clock_at == math.inf:
            self._clock_at = t
        joints = self.model.joint_positions(np.asarray(f, dtype=np.float64))
        body = joints[_BODY]
        self._recent.append((t, f, body))
        while self._recent and self._recent[0][0] < t - self.rule.pre_s - 1e-9:
            self._recent.popleft()
        self._body.append((t, body))
        while len(self._body) > 1 and t - self._body[1][0] >= self.rule.end_s:  # the oldest kept: end_s ago or more
            self._body.popleft()
        event = self.reach.update(body_wrist(joints), t)
        msgs: list[Message] = []
        if event is None and not self.reach.active and self._moved_away(body):
            return self._unseen(t)  # said again once the body is still, unless a reach starts first
        if event is not None and event.event == "start":
            self._rest_said = True  # the person seen, reaching: no rest (of a moving hand) to say, now or at its end
        elif (self.announce_rest and not self._rest_said and event is None and not self.reach.active
              and self.reach.settled and self._still() and self._recent[0][0] >= self._clock_at
              and self._recent[0][0] > self._ended_at):  # its poses on the clock, none of the last reach's
            self._rest_said = True
            msgs = self._at_rest()
        if event is not None and event.event == "start":
            self.reaches += 1
            first = [r for r in self._recent if r[0] >= event.stamp - 1e-9 and r[0] > self._ended_at] or [(t, f, body)]
            msgs += [self._start(first[0][0], LIVE_CLASS)]
            return msgs + [self._pose(s, g, b) for s, g, b in first]
        if not self.reach.active and event is None:
            return msgs
        msgs.append(self._pose(t, f, body))
        if event is not None and event.event == "end":
            self._ended_at = t  # no pose of the ended reach is a pose of the next one
            return msgs + [self._end(t, whole=not event.forced)]
        return msgs

    def lose(self, last: float, recording_ended: bool = False) -> list[Message]:
        """The track is lost (a gap, another body, the tracker stopping): a reach under way is ``lost`` at ``last``.

        So is the ended demonstration that showed where the person is, unless ``recording_ended`` (the end of a
        recording played: the person stands as last seen, as at a replayer's end). Everything about the track is
        forgotten: the next frames start a new one (its rest learnt, and said, again).
        """
        if self.reach.active:
            msgs = [self._marker(last, "lost", self._class)]
            self.lost += 1
        elif self._shown is not None and not recording_ended:
            msgs = self._unseen(last)
        else:
            msgs = []
        self.reach.reset()
        self._recent.clear()
        self._body.clear()
        self._clock_at = -math.inf
        self._ended_at = -math.inf  # a sensor restarted, or a clock stepped back: its frames may precede the last end
        self._rest_said = False
        self._shown = None
        return msgs

    def say_again(self) -> None:
        """Publish the person at rest again (once still, no reach under way), as at a track's start.

        For an executor that (re)appeared: one started anew has no prediction, and one that saw this tracker go
        (a lost link) holds until a demonstration starts. Before, the person at rest was said once per track, and
        a restarted executor held until the person's next reach.
        """
        self._rest_said = False

    def _moved_away(self, body: np.ndarray) -> bool:
        """Whether a point of ``body`` ``(3, 3)`` is over ``moved_m`` from every place the shown demonstration had."""
        if self._shown is None:
            return False
        nearest = np.linalg.norm(self._shown - body, axis=-1).min(axis=0)  # (3,): each point's nearest place
        return bool(nearest.max() > self.moved_m)

    def _still(self) -> bool:
        """Whether the body's points over the last ``end_s`` lie within ``end_m`` (rms) of their mean, and drift less.

        The reach rule's test of a hand come to rest, on the body: a person walking with the arm still is settled for
        the rule (it watches the wrist in the body's frame), and was said to be at rest, at one place of the walk. The
        spread alone lets a slow, steady motion through: a person turning in place at 10 deg/s (a shoulder 4 cm in a
        second, 1 cm rms) was said at rest one frame after the turn had lost them, still turning. So no point may
        have moved ``end_m`` either, from the mean of the window's first third to its last (still under 2 cm of noise
        per axis at 30 Hz: 1.1 cm median, 2.3 cm at most in 20 s; that turn: 2.9 cm).
        """
        if self._body[-1][0] - self._body[0][0] < self.rule.end_s - 1e-9:
            return False
        body = np.array([b for _, b in self._body])  # (N, 3, 3)
        third = max(1, len(body) // 3)
        drift = float(np.linalg.norm(body[-third:].mean(axis=0) - body[:third].mean(axis=0), axis=-1).max())
        return spread(body) < self.rule.end_m and drift < self.rule.end_m

    def _unseen(self, t: float) -> list[Message]:
        """The ended demonstration lost at ``t``: the person is no longer where it showed them.

        The reach rule goes on as it was: the hand's rest is in the body's frame, wherever the body is. Relearning it
        here (it was, for a day) held every reach back by a second when the body moved first: the paper library's
        compound_0 #0 and #3 lean or step 10 cm before the wrist leaves its rest, and their reaches started 39 frames
        after their onsets instead of 14 and 9 (`foresight bench tracker`).
        """
        self.unseen += 1
        self._shown = None
        self._rest_said = False  # said again where the person stands still next, unless a reach starts first
        return [self._marker(t, "lost", self._class)]

    def _at_rest(self) -> list[Message]:
        """The person standing still, as a demonstration of its own (class :data:`AT_REST`), started and ended."""
        self.rests += 1
        frames = list(self._recent)[-REST_POSES:]
        self._ended_at = frames[-1][0]  # the next reach's first poses come after these (its stamps never go back)
        return [self._start(frames[0][0], AT_REST), *(self._pose(s, g, b) for s, g, b in frames),
                self._end(frames[-1][0])]

    def _start(self, t: float, class_name: str) -> DemoMarker:
        self.demo_id += 1
        self._index = 0
        self._class = class_name
        self._path = []
        self._shown = None  # this demonstration shows the person now
        return DemoMarker(stamp=t, tick=-1, demo_id=self.demo_id, event="start", true_class=-1,
                          class_name=class_name, n_samples=0)

    def _end(self, t: float, whole: bool = True) -> DemoMarker:
        """The end marker; the demonstration's places kept, to tell when the person has left them.

        ``whole`` False (a reach ended by ``max_s``, the hand still moving: no reach, a walk with the arm swinging,
        say): only its last pose's places. A review: a walk taken for a 10 s reach left its whole path as the
        person's places, and walking on along it with the arm still was no loss.
        """
        self._shown = np.array(self._path if whole else self._path[-1:])
        return self._marker(t, "end", self._class)

    def _pose(self, t: float, f: np.ndarray, body: np.ndarray) -> HumanPose:
        features = np.asarray(f, dtype=np.float64).copy()
        # the fit follows the yaw continuously from its first guess: a track begun on the other side of +-pi, or a
        # person who turned round, published it 2 pi off the libraries' convention (recognised 10 of 40 reaches)
        features[_YAW] = (features[_YAW] + math.pi) % (2 * math.pi) - math.pi
        pose = HumanPose(stamp=t, tick=-1, tick_last=True, demo_id=self.demo_id, index=self._index,
                         features=features)
        self._index += 1
        self._path.append(body)
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
