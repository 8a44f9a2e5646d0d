"""Poses at the motion library's rate, whatever the sensor's: the tracker's output clock.

The predictor reads a pose's index as its time (the libraries' poses came at 30 a second), so a sensor at 120 Hz,
published a pose per frame, had every reach's indices run 4x too fast (a quarter of the way in, its time feature
stood at the model's last index), and one at 15 Hz 2x too slow (docs/keypoints.md measures what it does to
recognition, and why a pose per frame at 60 Hz happened to recognise more early on). :class:`PoseClock` puts the
tracker's smoothed frames on the library's clock: while the sensor's rate is within ``enter`` of it, each frame is
a pose (no resampling, no added delay); once it is further off, poses are made at ``rate_hz`` from the first such
frame on, each interpolated linearly between the smoothed frames on either side of its time, so a pose is never
later than the newest frame. It goes back to a pose per frame when the sensor comes within ``leave`` (a
hysteresis: a sensor near the bound does not flap between the two).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PoseClock"]


@dataclass
class PoseClock:
    """The tracker's output clock: a pose per frame, or poses resampled to ``rate_hz``.

    Args:
        rate_hz: The motion library's pose rate.
        enter: Resample once the sensor's rate is off ``rate_hz`` by more than this fraction.
        leave: A pose per frame again once it is within this fraction.

    Attributes:
        resampling: Whether the poses are resampled now.
        made: Poses made by resampling (not frames passed through).
    """

    rate_hz: float
    enter: float = 0.10
    leave: float = 0.05
    resampling: bool = False
    made: int = 0
    _anchor: float = math.nan  # the first resampled pose's time (nan: none yet)
    _n: int = 0  # the next pose's number on the grid from _anchor

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0 and math.isfinite(self.rate_hz)):
            raise ValueError(f"PoseClock: rate_hz must be a finite number > 0, got {self.rate_hz}")
        if not 0 <= self.leave <= self.enter:
            raise ValueError(f"PoseClock: need 0 <= leave <= enter, got leave {self.leave}, enter {self.enter}")

    def follow(self, sensor_hz: float | None) -> bool:
        """Take the sensor's measured rate (None: not known yet); whether resampling starts with it."""
        if sensor_hz is None or not sensor_hz > 0:
            return False
        off = abs(sensor_hz / self.rate_hz - 1.0)
        if not self.resampling and off > self.enter:
            self.resampling, self._anchor = True, math.nan
            return True
        if self.resampling and off < self.leave:
            self.resampling = False
        return False

    def poses(self, last: tuple[float, np.ndarray] | None, stamp: float, f: np.ndarray
              ) -> list[tuple[float, np.ndarray]]:
        """The poses up to a new smoothed frame, while resampling.

        Args:
            last: The previous smoothed frame ``(stamp, (12,) features)``, or None (the first of a track).
            stamp: This frame's stamp (s), after ``last``'s.
            f: ``(12,)`` its smoothed features.

        Returns:
            ``(time, (12,) features)`` for each pose time in ``(last's stamp, stamp]`` on the ``rate_hz`` grid that
            starts at the first frame resampled (that frame itself the first pose).
        """
        f = np.asarray(f, dtype=np.float64)
        if math.isnan(self._anchor) or last is None:
            self._anchor, self._n = stamp, 1
            self.made += 1
            return [(stamp, f.copy())]
        t0, f0 = last
        out = []
        # the grid's times from its anchor (not a running sum, which drifts over a long track)
        while (t := self._anchor + self._n / self.rate_hz) <= stamp + 1e-9:
            a = (t - t0) / (stamp - t0)
            out.append((t, f0 + a * (f - f0)))
            self._n += 1
        self.made += len(out)
        return out

    def reset(self) -> None:
        """A new track: a pose per frame until the sensor's rate is measured again."""
        self.resampling, self._anchor = False, math.nan
