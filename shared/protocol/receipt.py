"""The checks a service runs on every payload it receives: decode, values, per-sender order.

:class:`Receipt` is what the services' thin Zenoh loops call (through ``shared.transport``'s
subscriptions, or directly in the executor's logger): :func:`~shared.protocol.codec.decode` (form and
sizes), :func:`~shared.protocol.validation.check_values` (meaning and the receiver's expectations)
and :class:`SenderOrder` (ticks and sequence numbers monotonic per sender). Every failure is a
:class:`~shared.protocol.schema.ProtocolError` with its ``reason``. No Zenoh here: the sender is a
string the transport gives (the publishing session's id, sent as the sample's attachment).

Order rules, per key and sender:

* ``tick`` (when >= 0) never decreases; ``ClockTick.tick`` strictly increases. A tick of 0 after a
  higher one starts a new lock-step run and resets that sender's record on that key.
* ``HumanPose``: ``(demo_id, index)`` strictly increases; ``DemoMarker``: ``(demo_id, start < end < lost)``
  strictly increases; ``Plan.step`` and ``HumanKeypoints.frame`` strictly increase.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TypeVar

from .codec import decode
from .messages import ClockTick, DemoMarker, HumanKeypoints, HumanPose, Plan
from .schema import Message, ProtocolError
from .validation import Expectations, check_values

__all__ = ["SenderOrder", "Receipt", "MAX_SENDERS"]

M = TypeVar("M", bound=Message)

MAX_SENDERS = 1024
"""Senders remembered per receipt; the oldest record is dropped beyond (memory stays bounded)."""


@dataclass
class _Last:
    tick: int = -1
    seq: tuple[int, ...] | None = None


def _sequence(msg: Message) -> tuple[int, ...] | None:
    if isinstance(msg, HumanPose):
        return (msg.demo_id, msg.index)
    if isinstance(msg, DemoMarker):
        # then its end or its loss; a loss may follow the end (the person left where the demonstration showed them)
        return (msg.demo_id, {"start": 0, "end": 1}.get(msg.event, 2))
    if isinstance(msg, Plan):
        return (msg.step,)
    if isinstance(msg, HumanKeypoints):
        return (msg.frame,)
    return None


class SenderOrder:
    """Ticks and sequence numbers monotonic per (key, sender); thread-safe, bounded memory."""

    def __init__(self) -> None:
        self._last: dict[tuple[str, str], _Last] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        """The (key, sender) records held (at most :data:`MAX_SENDERS`)."""
        with self._lock:
            return len(self._last)

    def check(self, key: str, sender: str, msg: Message) -> None:
        """Accept ``msg`` (and remember it) or raise.

        Raises:
            ProtocolError: reason ``tick-order`` or ``sequence-order``; nothing is remembered then.
        """
        tick = int(getattr(msg, "tick", -1))
        seq = _sequence(msg)
        with self._lock:
            last = self._last.pop((key, sender), None)  # re-inserted below: the dict's order is least recent first
            if last is None:
                if len(self._last) >= MAX_SENDERS:  # read at call time, so tests can lower it
                    self._last.pop(next(iter(self._last)))  # the sender heard from least recently, not the oldest:
                last = _Last()  # a flood of made-up sender ids cannot push out a sender that is talking
            self._last[(key, sender)] = last
            if tick == 0 and last.tick > 0:  # a new lock-step run
                last.tick, last.seq = -1, None
            t = msg.TYPE
            if tick >= 0 and last.tick >= 0:
                if tick < last.tick or (isinstance(msg, ClockTick) and tick == last.tick):
                    raise ProtocolError(f"{t}.tick: {tick} after {last.tick} from the same sender", "tick-order")
            if seq is not None and last.seq is not None and seq <= last.seq:
                raise ProtocolError(f"{t}: sequence {seq} not after {last.seq} from the same sender",
                                    "sequence-order")
            if tick >= 0:
                last.tick = tick
            if seq is not None:
                last.seq = seq


class Receipt:
    """Decode, check the values and the order of every payload a service receives.

    Args:
        expect: What the receiver knows (default: generic bounds, clock ``auto``).
        order: Check per-sender order (default True).
    """

    def __init__(self, expect: Expectations | None = None, order: bool = True) -> None:
        self.expect = expect or Expectations()
        self.order = SenderOrder() if order else None

    def accept(self, key: str, payload: bytes, cls: type[M] | None, sender: str = "") -> M:
        """The message a payload on ``key`` carries, if it passes every check.

        Args:
            key: The key expression it arrived on.
            payload: The bytes.
            cls: The type the key carries (None: any type).
            sender: Who sent it (the publishing session's id; "" when unknown).

        Raises:
            ProtocolError: With the reason and a text naming the field.
        """
        msg = decode(payload, cls)
        self.check(key, msg, sender)
        return msg

    def check(self, key: str, msg: Message, sender: str = "") -> None:
        """Check an already decoded message (values, then order)."""
        check_values(msg, self.expect)
        if self.order is not None:
            self.order.check(key, sender, msg)
