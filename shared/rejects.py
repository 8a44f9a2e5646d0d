"""Counting rejected messages per key and reason, with rate-limited logging (one reusable object per service).

A service's thin loop calls :meth:`RejectCounter.reject` for every payload it refuses; the counter
keeps ``(key, reason)`` counts, logs at most one line per key per ``log_period_s`` and the first of each reason
on a key at once (each line says how many were refused on that key so far, by reason, so a flood never floods
the log, and a second kind of fault is never hidden behind the first), and gives a
one-line :meth:`RejectCounter.summary` for the service's status and shutdown lines.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

__all__ = ["RejectCounter"]

log = logging.getLogger("foresight.rejects")


class RejectCounter:
    """Counts and logs rejected messages per key and reason; thread-safe.

    Args:
        service: The service's name (starts each log line).
        log_period_s: Smallest time between two log lines about one key.
        clock: Monotonic clock (s).
    """

    def __init__(self, service: str, log_period_s: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.service = service
        self.log_period_s = log_period_s
        self._clock = clock
        self._by_reason: dict[tuple[str, str], int] = {}
        self._last_log: dict[str, float] = {}
        self._traced: set[str] = set()
        self._lock = threading.Lock()

    def reject(self, key: str, error: Exception | str, reason: str | None = None, said: bool = False) -> None:
        """Record one rejected message on ``key``.

        Args:
            key: The key expression it arrived on.
            error: Why (an exception's text names the field and the value).
            reason: The category (default: ``error.reason`` when it has one, else ``"malformed"``).
            said: The caller has just logged this one itself (its traceback): counted, its line starts the period.
        """
        why = reason or getattr(error, "reason", None) or "malformed"
        with self._lock:
            new_reason = (key, why) not in self._by_reason
            self._by_reason[(key, why)] = self._by_reason.get((key, why), 0) + 1
            now = self._clock()
            if said or (not new_reason and now - self._last_log.get(key, -float("inf")) < self.log_period_s):
                if said:
                    self._last_log[key] = now
                return
            self._last_log[key] = now
            counts = {r: n for (k, r), n in self._by_reason.items() if k == key}
        total = sum(counts.values())
        detail = ", ".join(f"{r} {n}" for r, n in sorted(counts.items()))
        text = str(error)[:300].replace("\r", "\\r").replace("\n", "\\n")  # a peer's text never starts a log line
        log.warning("%s: rejected a message on %s (%s): %s [%d so far: %s]", self.service, key, why, text, total,
                    detail)

    def unexpected(self, key: str, error: Exception, what: str) -> None:
        """Record a message refused by a bug of this process, not by the wire contract (reason ``handler``).

        Its traceback is logged the first time on each key (a peer repeating the message cannot flood the
        log with tracebacks), then it is counted and rate-limited like any :meth:`reject`. (It was filed as
        ``malformed``, blaming the sender, and said twice the first time.)

        Args:
            key: The key expression it arrived on.
            error: The exception the bug raised.
            what: What failed, e.g. ``"decoding a message"``.
        """
        with self._lock:
            first = key not in self._traced
            self._traced.add(key)
        if first:
            log.error("%s: %s on %s failed unexpectedly (this traceback once per key; later ones are counted)",
                      self.service, what, key, exc_info=error)
        self.reject(key, error, reason="handler", said=first)

    @property
    def counts(self) -> dict[str, int]:
        """Rejected messages per key."""
        out: dict[str, int] = {}
        with self._lock:
            for (key, _), n in self._by_reason.items():
                out[key] = out.get(key, 0) + n
        return out

    @property
    def by_reason(self) -> dict[tuple[str, str], int]:
        """Rejected messages per ``(key, reason)``."""
        with self._lock:
            return dict(self._by_reason)

    @property
    def total(self) -> int:
        """Total rejected messages."""
        with self._lock:
            return sum(self._by_reason.values())

    def summary(self) -> str:
        """One line: ``"none"`` or ``"key: reason n, reason n; key: ..."``."""
        by_key: dict[str, list[str]] = {}
        for (key, why), n in sorted(self.by_reason.items()):
            by_key.setdefault(key, []).append(f"{why} {n}")
        return "; ".join(f"{k}: {', '.join(v)}" for k, v in by_key.items()) or "none"
