"""The One-Euro filter (Casiez, Roussel and Vogel, CHI 2012): jitter removed at rest, little lag in motion.

A first-order low-pass filter per value whose cutoff rises with the value's speed: ``fc = min_cutoff +
beta |dx/dt|`` (the speed itself low-passed at ``d_cutoff``). A sensor's centimetre jitter on a still person
is smoothed at ``min_cutoff``; a reach, fast, passes with a higher cutoff, so it lags less than a slow motion
would (about 2 frames at 30 Hz with the tracker's defaults: docs/keypoints.md). Frames may come at any interval
(the smoothing factor follows each frame's own ``dt``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["OneEuroFilter", "smooth_sequence"]


def _alpha(cutoff_hz: np.ndarray | float, dt: float) -> np.ndarray | float:
    tau = 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz))
    return 1.0 / (1.0 + tau / dt)


class OneEuroFilter:
    """A One-Euro filter over a vector of values.

    Args:
        min_cutoff_hz: Cutoff at rest (Hz): lower, smoother and more lag on a still person.
        beta: How fast the cutoff rises with speed (per unit of the value's speed).
        d_cutoff_hz: Cutoff of the speed estimate (Hz).
    """

    def __init__(self, min_cutoff_hz: float = 1.0, beta: float = 0.5, d_cutoff_hz: float = 1.0) -> None:
        if not (min_cutoff_hz > 0 and d_cutoff_hz > 0 and beta >= 0):
            raise ValueError(f"One-Euro filter: cutoffs must be > 0 and beta >= 0, got min_cutoff_hz={min_cutoff_hz}, "
                             f"beta={beta}, d_cutoff_hz={d_cutoff_hz}")
        self.min_cutoff_hz = min_cutoff_hz
        self.beta = beta
        self.d_cutoff_hz = d_cutoff_hz
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next value passes unchanged."""
        self._x: np.ndarray | None = None
        self._dx: np.ndarray | None = None
        self._t: float | None = None

    def __call__(self, x: np.ndarray, t: float) -> np.ndarray:
        """The filtered value of ``x`` ``(N,)`` observed at time ``t`` (s; a time not after the last one resets)."""
        x = np.asarray(x, dtype=np.float64)
        if self._x is None or self._t is None or t <= self._t:
            self._x, self._dx, self._t = x.copy(), np.zeros_like(x), t
            return x.copy()
        dt = t - self._t
        dx = (x - self._x) / dt
        assert self._dx is not None
        self._dx = self._dx + _alpha(self.d_cutoff_hz, dt) * (dx - self._dx)
        a = _alpha(self.min_cutoff_hz + self.beta * np.abs(self._dx), dt)
        self._x = self._x + a * (x - self._x)
        self._t = t
        return self._x.copy()


def smooth_sequence(values: np.ndarray, rate_hz: float, min_cutoff_hz: float = 1.0, beta: float = 0.5) -> np.ndarray:
    """A whole recorded sequence through one fresh :class:`OneEuroFilter`, a value every ``1 / rate_hz`` s.

    What the tracker does to a person's frames as they come, done to a recording at once (the tracker's reach start
    on the library, :func:`services.tracker.reach.recorded_start`; the novelty test's calibration through the
    sensor, :func:`services.predictor.novelty.through_sensor`).

    Args:
        values: ``(T, N)`` the sequence, one row per sample.
        rate_hz: Samples per second (> 0).
        min_cutoff_hz: The filter's cutoff at rest (Hz).
        beta: How fast its cutoff rises with speed.

    Returns:
        ``(T, N)`` float64: the filtered sequence; row 0 is ``values[0]``.
    """
    if not rate_hz > 0:
        raise ValueError(f"smooth_sequence: rate_hz must be > 0, got {rate_hz}")
    values = np.asarray(values, dtype=np.float64)
    smooth = OneEuroFilter(min_cutoff_hz, beta)
    return np.array([smooth(x, k / rate_hz) for k, x in enumerate(values)]).reshape(values.shape)
