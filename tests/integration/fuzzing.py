"""Fuzz payloads for every key: random, truncated, bit-flipped, wrong-schema, oversized and absurd messages.

:class:`Fuzzer` turns one genuine message per key (its template, re-stamped with the wall clock for
every payload) into a stream of :class:`Case` payloads. Each case says whether it must be refused
(``must_refuse``) and, where the reason does not depend on who receives it, which reason the
executor gives (``reason``). Bit flips may still decode to a plausible message and be accepted; so may
the first message (the anchor) of an order case, which the next one then regresses from. The fuzzer
publishes without an attachment, so its messages are one sender of their own.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from shared.protocol import ClockTick, DemoMarker, HumanPose, Message, OccupancyGrid, Plan, RobotState, encode
from shared.protocol import limits as L

CATEGORIES = ("random", "truncated", "bitflip", "wrong-schema", "oversized-declared", "oversized-real", "absurd",
              "order")
REAL_OVERSIZED_PER_KEY = 3
"""Payloads over MAX_PAYLOAD_BYTES (16 MiB each) sent per key; other real oversize cases are small."""


@dataclass
class Case:
    """One fuzz payload."""

    category: str
    name: str
    payload: bytes
    must_refuse: bool
    reason: str | None = None
    sha1: bytes = b""
    head: bytes = b""

    @property
    def digest(self) -> bytes:
        """SHA-1 of the payload (kept when the payload itself is dropped)."""
        return self.sha1 or hashlib.sha1(self.payload).digest()


def raw_map(msg: Message) -> dict[str, Any]:
    """The msgpack map of a (valid) message, to break at the wire level."""
    return msgpack.unpackb(encode(msg), raw=False)


def pack(m: dict[str, Any]) -> bytes:
    return msgpack.packb(m, use_bin_type=True)


def arr(dtype: str, values: Any, shape: list[int] | None = None) -> dict[str, Any]:
    a = np.asarray(values, dtype=np.dtype(dtype))
    return {"dtype": a.dtype.str, "shape": list(a.shape) if shape is None else shape, "data": a.tobytes()}


def _set(msg: Message, **fields: Any) -> bytes:
    """``msg`` with some fields replaced, packed at the wire level (values encode would refuse too)."""
    m = raw_map(msg)
    m.update(fields)
    return pack(m)


Absurd = Callable[[Any, int], tuple[str, bytes, str | None]]


def _absurd_cases(cls: type) -> list[Absurd]:  # noqa: C901 - one table per message type
    """Well-formed (or nearly) but absurd messages of one type: (name, payload, executor's reason)."""
    future = [lambda m, i: ("stamp +1 h", encode(dataclasses.replace(m, stamp=time.time() + 3600)), "stamp-future"),
              lambda m, i: ("stamp 0", encode(dataclasses.replace(m, stamp=0.0)), "stamp-past")]
    if cls is HumanPose:
        return future + [
            lambda m, i: ("feature NaN", _set(m, features=arr("<f8", np.r_[np.nan, m.features[1:]])), "non-finite"),
            lambda m, i: ("feature 1e303", encode(dataclasses.replace(m, features=np.r_[m.features[:11], 1e303])),
                          "out-of-range"),
            lambda m, i: ("tick in real time", encode(dataclasses.replace(m, tick=5, stamp=1.1)), "mismatch"),
            lambda m, i: ("index -1", _set(m, index=-1), "invariant"),
        ]
    if cls is DemoMarker:
        return future + [
            lambda m, i: ("n_samples 1e12", encode(dataclasses.replace(m, n_samples=10 ** 12)), "out-of-range"),
            lambda m, i: ("event middle", _set(m, event="middle"), "invariant"),
            lambda m, i: ("class 1e6", encode(dataclasses.replace(m, true_class=10 ** 6)), "out-of-range"),
        ]
    if cls.TYPE == "ClassPosterior":
        return future + [
            lambda m, i: ("posterior 7",
                          _set(m, posterior=arr("<f8", np.r_[7.0, -6.0, np.zeros(m.posterior.size - 2)])), "invariant"),
            lambda m, i: ("posterior NaN", _set(m, posterior=arr("<f8", np.full(len(m.posterior), np.nan))),
                          "non-finite"),
            lambda m, i: ("index -5", encode(dataclasses.replace(m, index=-5)), "out-of-range"),
        ]
    if cls is OccupancyGrid:
        return future + [
            lambda m, i: ("occupancy 7.0", _set(m, values=arr("<f8", np.full(len(m.values), 7.0))), "shape"),
            lambda m, i: ("resolution 1e303", encode(dataclasses.replace(m, resolution=1e303)), "out-of-range"),
            lambda m, i: ("origin moved", encode(dataclasses.replace(m, origin=m.origin + 0.37)), "mismatch"),
            lambda m, i: ("index outside", _set(m, indices=arr("<u4", [2 ** 31]), values=arr("|u1", [200])),
                          "invariant"),
        ]
    if cls is Plan:
        return future + [
            lambda m, i: ("waypoint inf", _set(m, trajectories=arr("<f4", np.full(m.trajectories.shape, np.inf))),
                          "non-finite"),
            lambda m, i: ("q out of limits", encode(dataclasses.replace(m, trajectories=m.trajectories + 10.0)),
                          "joint-limits"),
            lambda m, i: ("dt 1e303", encode(dataclasses.replace(m, dt=1e303)), "out-of-range"),
            lambda m, i: ("joints reversed", encode(dataclasses.replace(m, joint_names=m.joint_names[::-1])),
                          "mismatch"),
            lambda m, i: ("cost NaN", _set(m, cost_total=arr("<f8", np.full(len(m.cost_total), np.nan))),
                          "invariant"),
        ]
    if cls is RobotState:
        def far(m: RobotState) -> np.ndarray:
            q = m.q.copy()
            q[0], q[-2] = -15532.0, 93542.0  # issue 12's torso and elbow
            return q
        return future + [
            lambda m, i: ("q -15532", encode(dataclasses.replace(m, q=far(m))), "joint-limits"),
            lambda m, i: ("qd 5.5e303", encode(dataclasses.replace(m, qd=np.full(len(m.q), 5.5e303))), "velocity"),
            lambda m, i: ("q NaN", _set(m, q=arr("<f8", np.full(len(m.q), np.nan))), "non-finite"),
            lambda m, i: ("joints renamed",
                          encode(dataclasses.replace(m, joint_names=[f"j{k}" for k in range(m.q.size)])), "mismatch"),
            lambda m, i: ("goal 1e6", encode(dataclasses.replace(m, goal=10 ** 6)), "out-of-range"),
        ]
    # ClockTick: in a real-time run every clock tick is refused (mismatch); these also break its own rules
    return [
        lambda m, i: ("period 1e303", encode(dataclasses.replace(m, period=1e303, stamp=5e303)), None),
        lambda m, i: ("stamp not tick x period", encode(dataclasses.replace(m, stamp=m.stamp + 7.0)), None),
        lambda m, i: ("tick -5", _set(m, tick=-5), "invariant"),
        lambda m, i: ("tick 2^62", encode(dataclasses.replace(m, tick=2 ** 62, stamp=0.2 * 2 ** 62)), None),
    ]


def _oversized_declared(m: Message) -> tuple[bytes, str]:
    """An array axis declared far over its limit with no data behind it."""
    raw = raw_map(m)
    for name in ("q", "trajectories", "posterior", "indices", "features"):
        if name in raw:
            shape = list(raw[name]["shape"])
            shape[0] = 2 ** 40
            raw[name]["shape"] = shape
            return pack(raw), "shape" if name == "features" else "too-large"
    raw["tick"] = 2 ** 63  # ClockTick: no array; a counter far over its limit
    return pack(raw), "out-of-range"


def _oversized_real(m: Message, big: bool) -> tuple[bytes, str | None]:
    """Real bytes over a limit: a payload over MAX_PAYLOAD_BYTES, or an axis over its limit with its data."""
    if big:
        return pack({"_type": m.TYPE, "_v": 1, "pad": b"\0" * L.MAX_PAYLOAD_BYTES}), "too-large"
    raw = raw_map(m)
    if isinstance(m, RobotState):
        d = L.MAX_JOINTS + 1
        raw.update(q=arr("<f8", np.zeros(d)), qd=arr("<f8", np.zeros(d)), joint_names=[f"j{k}" for k in range(d)])
    elif isinstance(m, Plan):
        raw["trajectories"] = arr("<f4", np.zeros((1, L.MAX_WAYPOINTS + 1, len(m.joint_names))))
        for name in ("cost_smoothness", "cost_obstacle", "cost_human", "cost_total"):
            raw[name] = arr("<f8", [1.0])
        raw.update(valid=arr("|b1", [True]), goal_names=["g"], chosen=0)
    elif m.TYPE == "ClassPosterior":
        n = L.MAX_CLASSES + 1
        raw.update(posterior=arr("<f8", np.full(n, 1.0 / n)), log_likelihood=arr("<f8", np.zeros(n)),
                   class_names=[f"c{k}" for k in range(n)])
    elif isinstance(m, OccupancyGrid):
        raw["dims"] = arr("<i4", [2000, 2000, 2000])  # issue 12: the planner allocated 29.8 GiB for this
        raw.update(indices=arr("<u4", [5]), values=arr("|u1", [9]))
    elif isinstance(m, HumanPose):
        raw["features"] = arr("<f8", np.zeros(13))
        return pack(raw), "shape"
    else:  # DemoMarker, ClockTick: strings over their limit
        raw["class_name" if isinstance(m, DemoMarker) else "_type"] = "x" * (L.MAX_STRING_CHARS * 4)
        return pack(raw), "too-large" if isinstance(m, DemoMarker) else "wrong-type"
    return pack(raw), "too-large"


def _order(m: Message, i: int) -> list[tuple[str, bytes, bool, str | None]]:
    """An anchor (plausible, may be accepted) and a message regressing from it (refused)."""
    if isinstance(m, HumanPose):
        d = 10 ** 6 + i
        return [("anchor", encode(dataclasses.replace(m, demo_id=d, index=50)), False, None),
                ("index back", encode(dataclasses.replace(m, demo_id=d, index=10)), True, "sequence-order")]
    if isinstance(m, DemoMarker):
        d = 10 ** 6 + i
        return [("anchor", encode(dataclasses.replace(m, demo_id=d, event="end")), False, None),
                ("start after end", encode(dataclasses.replace(m, demo_id=d, event="start")), True, "sequence-order")]
    if isinstance(m, Plan):
        s = 10 ** 6 + 2 * i
        return [("anchor", encode(dataclasses.replace(m, step=s)), False, None),
                ("step back", encode(dataclasses.replace(m, step=s - 1)), True, "sequence-order")]
    # no sequence number in real time: a tick (>= 0), which a real-time receiver refuses as such
    return [("tick in real time", encode(dataclasses.replace(m, tick=3, stamp=0.7)), True, None)]


class Fuzzer:
    """Fuzz payloads for one key.

    Args:
        template: A genuine message of the key's type (re-stamped with the wall clock per payload).
        others: Genuine messages of the other types (the wrong-schema cases).
        seed: Random seed.
    """

    def __init__(self, template: Message, others: list[Message], seed: int) -> None:
        self.template = template
        self.others = others
        self.rng = random.Random(seed)
        self.absurd = _absurd_cases(type(template))
        self.big_sent = 0

    def _fresh(self) -> Message:
        return (dataclasses.replace(self.template, stamp=time.time()) if getattr(self.template, "tick", 0) == -1
                else self.template)

    def cases(self, i: int) -> list[Case]:
        """The payloads of round ``i`` (one category per round, in turn)."""
        cat = CATEGORIES[i % len(CATEGORIES)]
        m, rng = self._fresh(), self.rng
        if cat == "random":
            return [Case(cat, "random", os.urandom(rng.randrange(0, 300)), True)]
        if cat == "truncated":
            data = encode(m)
            return [Case(cat, "truncated", data[: rng.randrange(0, len(data))], True, "malformed")]
        if cat == "bitflip":
            data = bytearray(encode(m))
            for _ in range(rng.randint(1, 8)):
                pos = rng.randrange(len(data))
                data[pos] ^= 1 << rng.randrange(8)
            return [Case(cat, "bitflip", bytes(data), False)]
        if cat == "wrong-schema":
            if rng.random() < 0.5:
                return [Case(cat, "another key's message", encode(rng.choice(self.others)), True, "wrong-type")]
            return [Case(cat, "field mistyped", _set(m, stamp="yesterday"), True, "malformed")]
        if cat == "oversized-declared":
            payload, reason = _oversized_declared(m)
            return [Case(cat, "axis 2^40", payload, True, reason)]
        if cat == "oversized-real":
            big = self.big_sent < REAL_OVERSIZED_PER_KEY
            self.big_sent += big
            payload, reason = _oversized_real(m, big)
            return [Case(cat, "16 MiB" if big else "axis over its limit", payload, True, reason)]
        if cat == "absurd":
            name, payload, reason = self.absurd[(i // len(CATEGORIES)) % len(self.absurd)](m, i)
            return [Case(cat, name, payload, True, reason)]
        return [Case(cat, name, payload, refuse, reason) for name, payload, refuse, reason in _order(m, i)]


def clock_template() -> ClockTick:
    """A plausible lock-step clock tick (tick 5 of 0.2 s)."""
    return ClockTick(stamp=1.0, tick=5, period=0.2)
