"""A bounded FIFO between Zenoh's callback threads and one worker that drains it in batches.

Zenoh hands each sample to a callback; a service that spends longer on a message than the stream leaves between
two would queue them without bound inside Zenoh. The callback only appends to a :class:`Backlog`; the worker takes
everything waiting at once and decides what of it to process (the predictor: observe every pose, build a grid for
the newest; the tracker: fit the frames, thinned once they span too long to catch up).
"""

from __future__ import annotations

import collections
import threading
from typing import Generic, TypeVar

__all__ = ["Backlog"]

T = TypeVar("T")


class Backlog(Generic[T]):
    """A bounded FIFO of messages, drained in batches by one consumer.

    Args:
        limit: Most items held; :meth:`put` beyond it drops the oldest (counted in ``dropped``).
    """

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError(f"backlog limit must be >= 1, got {limit}")
        self.limit = limit
        self.dropped = 0
        self.peak = 0
        self._items: collections.deque[T] = collections.deque()
        self._cond = threading.Condition()

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)

    def put(self, item: T) -> None:
        """Append ``item`` (dropping the oldest when full) and wake the consumer."""
        with self._cond:
            if len(self._items) >= self.limit:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            self.peak = max(self.peak, len(self._items))
            self._cond.notify()

    def take_all(self, timeout: float) -> list[T]:
        """Everything waiting, oldest first; waits up to ``timeout`` s for the first item ([] if none)."""
        with self._cond:
            if not self._items:
                self._cond.wait(timeout)
            out = list(self._items)
            self._items.clear()
            return out

    def wake(self) -> None:
        """Wake a waiting :meth:`take_all` (e.g. to let the consumer see a stop request)."""
        with self._cond:
            self._cond.notify_all()
