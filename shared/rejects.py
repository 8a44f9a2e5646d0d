"""Counting rejected messages per key and reason, with rate-limited logging (one reusable object per service).

A service's thin loop calls :meth:`RejectCounter.reject` for every payload it refuses; the counter
keeps ``(key, reason)`` counts, logs at most one line per key per ``log_period_s`` and the first of each reason
on a key at once (each line says how many were refused on that key so far, by reason, so a flood never floods
the log, and a second kind of fault is never hidden behind the first), and gives a
one-line :meth:`RejectCounter.summary` for the service's status and shutdown lines.

It tracks at most ``max_keys`` keys besides the contract's own (``known_keys``, always one by one): a peer can
publish on any number of keys under the prefix, so the rejects on any further key are counted together under
:data:`OTHER_KEYS` (one key for the rate limit too), a flood of distinct keys neither grows the counter nor
floods the log, and junk on the first keys to arrive never hides a contract key's rejects among them. Keys and
texts are logged escaped: a peer's key or text never starts a log line of its own.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable

__all__ = ["RejectCounter", "OTHER_KEYS", "MAX_KEYS", "escaped"]

log = logging.getLogger("foresight.rejects")

MAX_KEYS = 32  # keys tracked one by one; a service hears about a dozen
OTHER_KEYS = "(other keys)"  # the bucket for the rejects on every key past the first MAX_KEYS


def escaped(text: str) -> str:
    """``text`` with line breaks and other control characters written as escapes (one log line stays one)."""
    text = text.replace("\r", "\\r").replace("\n", "\\n")
    return "".join(c if c.isprintable() else f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}"
                   for c in text)


class RejectCounter:
    """Counts and logs rejected messages per key and reason; thread-safe.

    Args:
        service: The service's name (starts each log line).
        log_period_s: Smallest time between two log lines about one key.
        clock: Monotonic clock (s).
        max_keys: Keys counted one by one besides ``known_keys``; the rejects on any further key are counted
            under :data:`OTHER_KEYS`.
        known_keys: The wire contract's keys (e.g. ``Keys(prefix).data_keys()``): always counted one by one.
    """

    def __init__(self, service: str, log_period_s: float = 1.0, clock: Callable[[], float] = time.monotonic,
                 max_keys: int = MAX_KEYS, known_keys: Iterable[str] = ()) -> None:
        self.service = service
        self.log_period_s = log_period_s
        self.max_keys = max_keys
        self.known_keys = frozenset(known_keys)
        self._clock = clock
        self._by_reason: dict[tuple[str, str], int] = {}
        self._keys: set[str] = set()  # the other keys counted one by one (at most max_keys)
        self._last_log: dict[str, float] = {}
        self._traced: set[str] = set()
        self._lock = threading.Lock()

    def _bucket(self, key: str) -> str:
        """The key ``key`` is counted under: itself, or :data:`OTHER_KEYS` past ``max_keys`` (lock held)."""
        if key in self._keys or key in self.known_keys:
            return key
        if len(self._keys) < self.max_keys:
            self._keys.add(key)
            return key
        return OTHER_KEYS

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
            bucket = self._bucket(key)
            new_reason = (bucket, why) not in self._by_reason
            self._by_reason[(bucket, why)] = self._by_reason.get((bucket, why), 0) + 1
            now = self._clock()
            if said or (not new_reason and now - self._last_log.get(bucket, -float("inf")) < self.log_period_s):
                if said:
                    self._last_log[bucket] = now
                return
            self._last_log[bucket] = now
            counts = {r: n for (k, r), n in self._by_reason.items() if k == bucket}
        total = sum(counts.values())
        detail = ", ".join(f"{r} {n}" for r, n in sorted(counts.items()))
        where = (f" on other keys past the first {self.max_keys}, counted as {OTHER_KEYS}"
                 if bucket == OTHER_KEYS else "")
        log.warning("%s: rejected a message on %s (%s): %s [%d so far%s: %s]", self.service, escaped(key[:200]),
                    escaped(why), escaped(str(error)[:300]), total, where, detail)

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
            bucket = self._bucket(key)
            first = bucket not in self._traced
            self._traced.add(bucket)
        if first:
            log.error("%s: %s on %s failed unexpectedly (this traceback once per key; later ones are counted)",
                      self.service, what, escaped(key[:200]), exc_info=error)
        self.reject(key, error, reason="handler", said=first)

    @property
    def counts(self) -> dict[str, int]:
        """Rejected messages per key (those past ``max_keys`` keys under :data:`OTHER_KEYS`)."""
        out: dict[str, int] = {}
        with self._lock:
            for (key, _), n in self._by_reason.items():
                out[key] = out.get(key, 0) + n
        return out

    @property
    def by_reason(self) -> dict[tuple[str, str], int]:
        """Rejected messages per ``(key, reason)`` (keys past ``max_keys`` as :data:`OTHER_KEYS`)."""
        with self._lock:
            return dict(self._by_reason)

    @property
    def total(self) -> int:
        """Total rejected messages."""
        with self._lock:
            return sum(self._by_reason.values())

    def summary(self) -> str:
        """One line: ``"none"`` or ``"key: reason n, reason n; key: ..."`` (keys escaped: services log it)."""
        by_key: dict[str, list[str]] = {}
        for (key, why), n in sorted(self.by_reason.items()):
            by_key.setdefault(escaped(key[:200]), []).append(f"{escaped(why)} {n}")
        return "; ".join(f"{k}: {', '.join(v)}" for k, v in by_key.items()) or "none"
