"""A periodic one-line summary at INFO of events that are each logged at DEBUG (e.g. one plan per step).

A service that acts many times a second logs each act at DEBUG (``--log-level DEBUG`` shows them) and,
every ``period_s`` of wall time and when it stops, one INFO line: how many, their durations' median
and maximum, and how often each outcome occurred.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable

import numpy as np

__all__ = ["PeriodicSummary"]


class PeriodicSummary:
    """Counts events (a duration and an outcome each) and logs them in one line per period.

    Args:
        logger: Where the line goes (INFO).
        what: The events' name, e.g. ``"planner: plans"``.
        period_s: Wall seconds between lines.
        clock: Monotonic clock (tests pass their own).
    """

    def __init__(self, logger: logging.Logger, what: str, period_s: float = 10.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.what = what
        self.period_s = period_s
        self.clock = clock
        self._since = clock()
        self._ms: list[float] = []
        self._outcomes: Counter[str] = Counter()

    def add(self, duration_ms: float, outcome: str) -> None:
        """Count one event; log the summary when the period is over."""
        self._ms.append(float(duration_ms))
        self._outcomes[outcome] += 1
        if self.clock() - self._since >= self.period_s:
            self.flush()

    def line(self) -> str:
        """The summary of the events since the last line ("" when there were none)."""
        if not self._ms:
            return ""
        ms = np.asarray(self._ms)
        seconds = self.clock() - self._since
        outcomes = ", ".join(f"{name} {n}" for name, n in self._outcomes.most_common())
        return (f"{self.what}: {len(ms)} in the last {seconds:.1f} s, {float(np.median(ms)):.0f} ms median, "
                f"{float(ms.max()):.0f} ms max; {outcomes}")

    def flush(self) -> None:
        """Log the summary of the events since the last line (nothing when there were none) and start anew."""
        text = self.line()
        if text:
            self.logger.info("%s", text)
        self._since = self.clock()
        self._ms.clear()
        self._outcomes.clear()
