"""What the fuzz tests share: publishing the fuzz, watching genuine traffic, checking the executor's log, RSS."""

from __future__ import annotations

import hashlib
import json
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import zenoh
from mcap.reader import make_reader

from shared.config import ZenohConfig
from shared.protocol import REASONS, Expectations, Keys, Message, ProtocolError, Receipt
from shared.recording.schemas import REJECTED_TOPIC
from shared.transport import sender_of, zenoh_config

from .fuzzing import Case, Fuzzer


def rss_mb(pid: int | str = "self") -> float:
    """Resident memory of a process (MB), from /proc."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")  # pragma: no cover - Linux only


def wait_until(pred: Callable[[], bool], timeout: float, step: float = 0.05) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return bool(pred())


def settle(total: Callable[[], int], timeout: float = 300.0, quiet_s: float = 2.0) -> None:
    """Wait until ``total()`` has not changed for ``quiet_s`` seconds (at most ``timeout``)."""
    end = time.monotonic() + timeout
    last, since = total(), time.monotonic()
    while time.monotonic() < end:
        time.sleep(0.2)
        now = total()
        if now != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return


class Watcher:
    """Genuine traffic (a sender id, accepted by a real-time receipt like the planner's), newest per key."""

    def __init__(self, session: zenoh.Session, keys: Keys, expect: Expectations) -> None:
        self.keys = keys
        self.receipt = Receipt(expect)
        self.latest: dict[str, Message] = {}
        self.accepted_at: dict[str, float] = {}
        self._sub = session.declare_subscriber(f"{keys.prefix}/**", self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        key, sender = str(sample.key_expr), sender_of(sample)
        types = self.keys.data_keys()
        if key not in types or not sender:  # the fuzzer publishes without a sender id
            return
        try:
            msg = self.receipt.accept(key, sample.payload.to_bytes(), types[key], sender)
        except ProtocolError:
            return
        self.latest[key] = msg
        self.accepted_at[key] = time.time()

    def close(self) -> None:
        self._sub.undeclare()


Sent = dict[str, list[Case]]


@contextmanager
def fuzz_session(cfg: ZenohConfig) -> Iterator[zenoh.Session]:
    """A session whose blocked publications wait (up to 10 min) instead of closing the link after 5 s.

    Zenoh's default (``transport/link/tx/queue/congestion_control/block/wait_before_close``, 5 s)
    closes the link to a subscriber that falls that far behind; the fuzzer, publishing with congestion
    control *block*, then simply waits for the slowest receiver (the executor).
    """
    conf = zenoh_config(cfg)
    conf.insert_json5("transport/link/tx/queue/congestion_control/block/wait_before_close", "600000000")
    session = zenoh.open(conf)
    try:
        yield session
    finally:
        session.close()


PROBE = b"route probe"
"""What the fuzzer sends until its route to the executor exists (refused as malformed where it arrives)."""
PACE_WINDOW = 32
"""Rounds the fuzzer may run ahead of the executor's progress (see :func:`publish_fuzz`)."""


def publish_fuzz(session: zenoh.Session, templates: dict[str, Message], rounds: int, seed: int = 0,
                 keep: Callable[[Case], bool] | None = None, progress: Callable[[], int] | None = None,
                 pace_key: str = "") -> Sent:
    """Publish ``rounds`` rounds of fuzz on every key of ``templates``; the cases sent, per key.

    The payloads themselves are not kept (only their digests, in :class:`Case`), so memory stays small.
    With ``progress`` (how many payloads on ``pace_key`` the executor has handled, exactly), the
    fuzzer stays within :data:`PACE_WINDOW` payloads of it (waiting at most 60 s at a time). Publish
    from a :func:`fuzz_session`: the fuzzer outruns the executor (one subscription that decodes,
    checks and logs every key), and by default Zenoh closes a link whose blocked messages wait more
    than 5 s, so the rest of the fuzz would never reach it.
    """
    fuzzers = {k: Fuzzer(m, [o for kk, o in templates.items() if kk != k], seed=seed + i)
               for i, (k, m) in enumerate(templates.items())}
    pubs = {k: session.declare_publisher(k, congestion_control=zenoh.CongestionControl.BLOCK) for k in templates}
    sent: Sent = {k: [] for k in templates}
    try:
        if progress is not None:  # Zenoh does not buffer: wait until the route to the executor exists
            start = progress()
            while progress() == start:  # a probe may arrive, or not, or late: the checks leave them out
                pubs[pace_key].put(PROBE)
                sent[pace_key].append(Case("probe", "route probe", b"", True, "malformed", head=PROBE))
                wait_until(lambda s=start: progress() > s, 0.5)
        for i in range(rounds):
            for k, fz in fuzzers.items():
                for case in fz.cases(i):
                    if keep is None or keep(case):
                        pubs[k].put(case.payload)
                        sent[k].append(Case(case.category, case.name, b"", case.must_refuse, case.reason,
                                            case.digest, case.payload[:64]))
            if i % 20 == 19:
                time.sleep(0.02)  # the genuine traffic keeps flowing in between
            if progress is not None:
                wait_until(lambda: len(sent[pace_key]) - progress() <= PACE_WINDOW, 60.0, step=0.02)
    finally:
        for p in pubs.values():
            p.undeclare()
    return sent


def check_executor_log(mcap: str, keys: Keys, sent: Sent, t_fuzz_end: float, counts: dict[str, int],
                       by_reason: dict[tuple[str, str], int], late_ok: bool = False) -> dict[str, Any]:
    """Check the executor's refusals and its MCAP log against what was sent: a per-key report with problems.

    Every payload that must be refused is not on its key's data channel; only bit flips and anchors
    may be; the executor refused exactly what it did not log (on the prediction keys, plus the
    predictor's lock-step-stamped answers to anchors it accepted: mismatch); the rejects channel holds
    one record per refusal, and each payload that must be refused has its record (found by its first
    64 bytes, which hold its stamp), with the expected reason where that is deterministic; a genuine
    message is logged on every key after the fuzz (but the clock, which ticks in lock-step).

    With ``late_ok``, a real-time case refused as ``stamp-past`` instead of its reason counts as
    ``late`` (the executor handled it more than ``STAMP_PAST_S`` after it was stamped: the stamp is
    checked first), not as a problem.
    """
    data: dict[str, set[bytes]] = {k: set() for k in sent}
    after: Counter[str] = Counter()
    records: dict[str, Counter[tuple[str, str]]] = {k: Counter() for k in sent}
    with open(mcap, "rb") as f:  # streamed: a long run's log is large
        for _, channel, m in make_reader(f).iter_messages():
            if channel.topic in data:
                data[channel.topic].add(hashlib.sha1(m.data).digest())
                after[channel.topic] += m.log_time / 1e9 > t_fuzz_end
            elif channel.topic == REJECTED_TOPIC:
                r = json.loads(m.data)
                assert r["reason"] in REASONS, r
                records.setdefault(r["key"], Counter())[(r["head_hex"], r["reason"])] += 1
    report = {}
    for k, cases in sent.items():
        problems: list[str] = []
        cases = [c for c in cases if c.category != "probe"]
        probes = records[k].pop((PROBE.hex(), "malformed"), 0)
        accepted = [c for c in cases if c.digest in data[k]]
        problems += [f"logged as data: {c.name}" for c in accepted if c.must_refuse]
        problems += [f"accepted: {c.category}" for c in accepted if c.category not in ("bitflip", "order")]
        n_rej, expected = counts.get(k, 0) - probes, len(cases) - len(accepted)
        slack = by_reason.get((k, "mismatch"), 0) if k in (keys.posterior, keys.occupancy) else 0
        if not expected <= n_rej <= expected + slack:
            problems.append(f"{n_rej} refused, {len(cases)} sent, {len(accepted)} logged as data")
        if sum(records[k].values()) != n_rej:
            problems.append(f"rejects channel has {sum(records[k].values())} records for {n_rej} refusals")
        left = Counter(records[k])
        by_head: dict[str, list[str]] = {}
        for (head, reason), n in left.items():
            by_head.setdefault(head, []).extend([reason] * n)
        lost = late = 0
        for c in sorted((c for c in cases if c.must_refuse), key=lambda c: c.reason is None):
            got = by_head.get(c.head.hex(), [])
            want = c.reason if c.reason is not None else (got[0] if got else None)
            if want in got:
                got.remove(want)
            elif late_ok and "stamp-past" in got:
                late += 1
                got.remove("stamp-past")
            elif not got:
                lost += 1
                problems.append(f"never refused: {c.category} {c.name}")
            else:
                problems.append(f"{c.category} {c.name}: refused as {sorted(set(got))}, expected {c.reason}")
                got.pop()
        if after[k] == 0 and k != keys.clock:
            problems.append("no genuine message logged after the fuzz")
        report[k] = {"sent": len(cases), "refused": n_rej, "accepted_from_fuzzer": len(accepted), "lost": lost,
                     "late": late,
                     "reasons": {r: n for (kk, r), n in sorted(by_reason.items()) if kk == k},
                     "problems": problems[:10] + ([f"... {len(problems) - 10} more"] if len(problems) > 10 else [])}
    return report


def problems_of(report: dict[str, Any]) -> dict[str, list[str]]:
    """The keys whose report lists problems."""
    return {k: r["problems"] for k, r in report.items() if r["problems"]}


def must_refuse_anywhere(sent: Sent) -> dict[str, int]:
    """Per key, the cases any receiver refuses whatever its clock and model (a lower bound for the others)."""
    return {k: sum(1 for c in cases if c.must_refuse and c.reason not in (None, "mismatch") and c.category != "probe")
            for k, cases in sent.items()}
