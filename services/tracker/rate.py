"""The sensor's frame rate, measured from the intervals between its frames' stamps.

The period is the median of the recent intervals, leaving out those under half of it or under
:data:`MIN_PERIOD_S`: frames that came in a burst (a link flushing after a stall) would otherwise shrink it, and a
gap bridged at that period would be filled with invented frames. A burst ends when its backlog is flushed; a sensor
that went faster (30 -> 120 Hz mid-track) goes on, and once a window of such short intervals in a row agree (within
25 % of their median) they are the period. A gap between two frames taken is bridged (:meth:`FrameRate.missed`) with
the frames the sensor's numbers say it lost, or, while the recent intervals are each a whole number of periods, with
as many as the gap holds periods less one.

The tracker keeps two: the rate of the frames it fits (the poses are made from them: bridging, resampling) and
the rate of every frame the sensor sends (what the user is told: a sensor at 120 Hz whose frames are fitted at 60,
or a 30 Hz one of which only every other frame is the person tracked, is still a 120 or 30 Hz sensor).
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["FrameRate", "MIN_PERIOD_S", "WHOLE_TOLERANCE"]

MIN_PERIOD_S = 1.0 / 500
"""The shortest frame interval taken for the sensor's period (500 Hz): shorter ones are frames of a burst."""

WHOLE_TOLERANCE = 0.25
"""How far (in periods) an interval of two or more periods may be from a whole number of them and still be the
sensor's: frames lost between two taken ones (:meth:`FrameRate.regular`)."""


class FrameRate:
    """Recent frame intervals -> the sensor's period.

    Args:
        window: Intervals the period is the median of (and short intervals in a row that make a new period).
    """

    def __init__(self, window: int = 15) -> None:
        self.window = window
        self._dts: deque[float] = deque(maxlen=window)    # recent intervals: the period
        self._short: deque[float] = deque(maxlen=window)  # intervals in a row under half of it (_faster)

    def add(self, dt: float) -> None:
        """One interval (s) between consecutive frames' stamps."""
        if dt >= MIN_PERIOD_S and (len(self._dts) < 3 or dt >= 0.5 * float(np.median(self._dts))):
            self._dts.append(dt)  # the sensor's period; a burst's intervals are left out
            self._short.clear()
        elif dt >= MIN_PERIOD_S:
            self._faster(dt)

    @property
    def period(self) -> float | None:
        """The median interval (s), once three are known; None before."""
        return float(np.median(self._dts)) if len(self._dts) >= 3 else None

    @property
    def hz(self) -> float | None:
        """Frames a second, once a whole window of intervals is known; None before."""
        return 1.0 / float(np.median(self._dts)) if len(self._dts) == self.window else None

    def regular(self, dt: float) -> bool:
        """Whether an interval of ``dt`` s is the sensor's: a period, or a whole number of them (frames lost between).

        One period within half of it either way (a sensor's jitter), two or more within :data:`WHOLE_TOLERANCE` of a
        whole number of them.
        """
        period = self.period
        if period is None:
            return False
        k = round(dt / period)
        return 0.5 * period <= dt <= 1.5 * period or (k >= 2 and abs(dt - k * period) <= WHOLE_TOLERANCE * period)

    def steady(self) -> bool:
        """Whether the last three intervals before the newest are the sensor's (:meth:`regular`).

        After a stall a backlog flushed a few ms apart is no sensor's period: a gap is bridged at it only while this
        holds. A sensor that loses frames regularly is steady: a 30 Hz one losing the wrist in every 4th frame
        (intervals of one and two periods) had no gap bridged, and its poses' time ran at 22.5 a second.
        """
        last = list(self._dts)[-4:-1] if len(self._dts) > 3 else list(self._dts)[:3]
        return self.period is not None and all(self.regular(dt) for dt in last)

    def missed(self, gap: float, dropped: int | None = None) -> int:
        """Frames missing in ``gap`` s between two frames taken, to be bridged: 0 while the period is not known.

        ``dropped``: the frames between, by the sensor's frame numbers (None: it numbers none). Those are bridged
        when the gap is as long as they make it (each within half a period of one): the sensor says what it lost.
        Otherwise the gap in periods, less one, while :meth:`steady` (never more than ``dropped``).
        """
        period = self.period
        if period is None:
            return 0
        if dropped is not None and dropped > 0 and 0.5 * period <= gap / (dropped + 1) <= 1.5 * period:
            return dropped
        if not self.steady():
            return 0
        n = max(0, round(gap / period) - 1)
        return n if dropped is None else min(n, max(dropped, 0))

    def reset(self) -> None:
        """Forget the intervals (the next frames may come from a sensor restarted at another rate)."""
        self._dts.clear()
        self._short.clear()

    def _faster(self, dt: float) -> None:
        """An interval under half the period: a burst's, or a sensor that went faster (30 -> 120 Hz mid-track).

        Once as many such intervals as the window holds came in a row, within 25 % of their median, they are the
        sensor's period (else a sensor that sped up was measured at its old rate for good, and its poses never
        resampled).
        """
        self._short.append(dt)
        if len(self._short) == self._short.maxlen:
            med = float(np.median(self._short))
            if all(abs(x - med) <= 0.25 * med for x in self._short):
                self._dts = deque(self._short, maxlen=self.window)
                self._short.clear()
