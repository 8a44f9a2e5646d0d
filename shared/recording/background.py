"""A bounded background worker: best-effort work (the Foxglove scene updates) off a receive path.

The executor logs every message from its Zenoh callback, and the plans it receives drive the robot.
Building a Foxglove update of a predicted occupancy (thousands of cubes as JSON, 13-22 ms on the
2-core machine) inside that callback delayed every message queued behind it, a plan included, and its
receive time with it: in real-time runs one plan in about seven arrived 40 ms late, the tail of the
occupancy -> plan latency (docs/planner.md, *Reaction time*). :class:`BackgroundWorker` runs such
work on its own thread: the caller only enqueues, and when the queue is full the item is dropped
(counted), never waited for, because the raw log and the robot come first.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["BackgroundWorker"]

log = logging.getLogger(__name__)

_STOP = object()


class BackgroundWorker:
    """Runs ``work(item)`` for each submitted item on one daemon thread, in submission order.

    Args:
        work: Called with each item; an exception is counted in :attr:`errors` and logged (rate-limited),
            the worker goes on.
        name: Thread name (shown in logs and debuggers).
        max_pending: Items that may wait; :meth:`submit` drops an item beyond them.

    Attributes:
        done: Items processed (with or without an error).
        dropped: Items refused: ``max_pending`` were already waiting, or :meth:`close` had begun.
        errors: Items whose ``work`` raised.
    """

    def __init__(self, work: Callable[[Any], None], name: str = "background", max_pending: int = 16) -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        self._work = work
        self._max_pending = int(max_pending)
        self._queue: queue.Queue[Any] = queue.Queue()  # bounded by submit, so that close always has room
        self._closed = False
        self._lock = threading.Lock()
        self.done = 0
        self.dropped = 0
        self.errors = 0
        self._busy = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any) -> bool:
        """Queue ``item`` without waiting; returns False (and counts a drop) when full or closed."""
        with self._lock:
            if self._closed:
                self.dropped += 1
                return False
            if self._queue.qsize() >= self._max_pending:  # may overstate (the worker takes items out meanwhile)
                self.dropped += 1
                return False
            self._queue.put_nowait(item)
        return True

    def close(self, timeout_s: float = 10.0) -> bool:
        """Process what is queued, then stop the thread; idempotent.

        Args:
            timeout_s: Longest wait for the queued items.

        Returns:
            Whether the thread finished within ``timeout_s`` (False: it is left running as a daemon).
        """
        with self._lock:
            if not self._closed:
                self._closed = True
                self._queue.put_nowait(_STOP)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.warning("%s: %d queued item(s) not processed within %.1f s", self._thread.name, self.pending,
                        timeout_s)
            return False
        return True

    @property
    def pending(self) -> int:
        """Items submitted and not processed yet (the one being processed included)."""
        return max(self._queue.qsize() - (1 if self._closed else 0), 0) + (1 if self._busy else 0)

    def _run(self) -> None:
        try:
            while True:
                item = self._queue.get()
                if item is _STOP:
                    return
                self._busy = True
                try:
                    self._work(item)
                except Exception:
                    self.errors += 1
                    if self.errors == 1 or self.errors % 100 == 0:
                        log.exception("%s: an item failed (%d so far)", self._thread.name, self.errors)
                self._busy = False
                self.done += 1
        except BaseException:  # not an Exception of work's: the thread ends here, say so
            log.exception("%s: stopped with %d item(s) not processed", self._thread.name, self.pending)
            raise
