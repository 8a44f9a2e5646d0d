"""A keypoint recording on a sensor's timeline: what ``foresight tracker --from FILE`` plays (pure: no Zenoh).

A keypoint recording (one ``<class>.csv`` of a keypoint library, docs/keypoints.md) holds demonstrations one
after another, each from rest to the goal. A sensor watching a person sees more: the person standing still
before the reach, the hand staying at the goal after it. So each demonstration is played as

1. its first frame (the first with every point seen) held for ``lead_s`` (at rest: the tracker learns where the
   hand rests, and no reach starts before it has);
2. its frames at ``rate_hz``, frame ``n`` at ``n / rate_hz`` s from the first (a frame missing from the file is
   a frame the sensor dropped);
3. its last frame (with every point seen) held for ``hold_s`` (the hand at the goal: the reach ends);
4. ``gap_s`` without frames (the person out of view; the tracker starts afresh), then the next demonstration.

Frame numbers count the sensor's frames, so they run on across the holds and the gap (a gap is dropped frames).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from shared.keypoints.library import KeypointDemo

from .config import PlaybackConfig

__all__ = ["PlayedFrame", "Playback"]


@dataclass(frozen=True)
class PlayedFrame:
    """One frame to send: ``t`` s from the start of the playback, the sensor's ``frame`` number, the positions."""

    t: float
    frame: int
    demo: int
    positions: np.ndarray  # (K, 3), NaN where missing


def _most_seen(positions: np.ndarray) -> np.ndarray:
    """The first of ``positions (T, K, 3)`` with the fewest points missing (a held frame must not lack one)."""
    return positions[int(np.argmin(np.isnan(positions).any(axis=-1).sum(axis=-1)))]


class Playback:
    """The timeline of a recording's demonstrations (see the module docstring).

    Args:
        demos: The recording's demonstrations (``shared.keypoints.library.read_keypoint_csv``), all with the same
            point names.
        config: Rate, holds, gap, loop.

    Raises:
        ValueError: No demonstration, or demonstrations with different point names.
    """

    def __init__(self, demos: list[KeypointDemo], config: PlaybackConfig) -> None:
        if not demos:
            raise ValueError("keypoint recording: no demonstration in it")
        if any(d.names != demos[0].names for d in demos):
            raise ValueError("keypoint recording: its demonstrations name different points")
        self.demos = demos
        self.config = config
        self.names = list(demos[0].names)

    def duration_s(self) -> float:
        """Seconds one pass over the recording takes."""
        return sum(self._length(d) for d in self.demos) / self.config.rate_hz

    def _length(self, demo: KeypointDemo) -> int:
        """Frames one demonstration takes on the timeline, its gap included."""
        c = self.config
        return (round(c.lead_s * c.rate_hz) + int(demo.frames[-1] - demo.frames[0]) + 1 + round(c.hold_s * c.rate_hz)
                + round(c.gap_s * c.rate_hz))

    def frames(self) -> Iterator[PlayedFrame]:
        """Every frame in order (endless with ``loop``)."""
        c = self.config
        lead, hold = round(c.lead_s * c.rate_hz), round(c.hold_s * c.rate_hz)
        n = 0  # the sensor's frame counter
        while True:
            for k, demo in enumerate(self.demos):
                first, last = _most_seen(demo.positions), _most_seen(demo.positions[::-1])
                for i in range(lead):
                    yield PlayedFrame((n + i) / c.rate_hz, n + i, k, first)
                n += lead
                for f, pos in zip(demo.frames - demo.frames[0], demo.positions, strict=True):
                    yield PlayedFrame((n + int(f)) / c.rate_hz, n + int(f), k, pos)
                n += int(demo.frames[-1] - demo.frames[0]) + 1
                for i in range(hold):
                    yield PlayedFrame((n + i) / c.rate_hz, n + i, k, last)
                n += hold + round(c.gap_s * c.rate_hz)
            if not c.loop:
                return
