"""The lock-step replayer's clock over real Zenoh: forged ticks refused, a late join said, a restarted run replayed."""

from __future__ import annotations

import logging
import threading
import time

from services.replayer.core import ReplayerConfig
from services.replayer.service import ReplayerService
from shared.protocol import ClockTick, DemoMarker, HumanPose, Keys
from shared.transport import Presence, TypedPublisher, open_session, subscribe_ordered

P = 0.2


class Stream:
    """A lock-step replayer streaming class 0's first demonstration (12 poses), one pose per tick, and its poses."""

    def __init__(self, zenoh_hub, small_lib, session, keys: Keys) -> None:
        self.service = ReplayerService(ReplayerConfig(mode="lockstep", classes=[0], indices=[0]), zenoh_hub(),
                                       small_lib)
        self.poses: list[HumanPose] = []
        self.cond = threading.Condition()
        self.sub = subscribe_ordered(session, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker}, self.add)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.service.run, args=(self.stop,), daemon=True)

    def add(self, msg) -> None:
        with self.cond:
            if isinstance(msg, HumanPose):
                self.poses.append(msg)
            self.cond.notify_all()

    def start(self, watcher: Presence) -> None:
        """Run the replayer until ``watcher`` sees it (its clock subscription is declared before its token)."""
        self.thread.start()
        deadline = time.monotonic() + 10
        while not watcher.is_alive("replayer"):
            assert time.monotonic() < deadline, "replayer never appeared"
            time.sleep(0.01)

    def tick(self, clock: TypedPublisher, n: int, period: float = P, answered: bool = True) -> None:
        """Publish ClockTick n; wait for its pose when it is to be ``answered`` (else a while)."""
        clock.put(ClockTick(stamp=n * period, tick=n, period=period))
        with self.cond:
            if answered:
                assert self.cond.wait_for(lambda: self.poses and self.poses[-1].tick == n, timeout=10.0), f"tick {n}"
            else:
                self.cond.wait(0.3)

    def end(self) -> None:
        self.stop.set()
        self.thread.join(timeout=10.0)
        assert not self.thread.is_alive()
        self.sub.undeclare()


def test_forged_ticks_leave_the_run_alone(zenoh_hub, small_lib, caplog):
    """Security off: one tick 1000000 from another session silenced the replayer for the rest of the run; a tick 0
    mid-run, a repeat, one slightly ahead or of another period shifted it. Each is refused, counted, said."""
    caplog.set_level(logging.WARNING, logger="foresight.rejects")
    first = zenoh_hub()
    keys = Keys(first.prefix)
    with open_session(first) as session, open_session(zenoh_hub()) as forger:
        stream = Stream(zenoh_hub, small_lib, session, keys)
        executor = Presence(session, keys, "executor")
        clock, forged = TypedPublisher(session, keys.clock), TypedPublisher(forger, keys.clock)
        try:
            stream.start(executor)
            for n in range(3):
                stream.tick(clock, n)
            for n, period in ((1_000_000, P), (0, P), (2, P), (3, 50.0), (4, P)):
                stream.tick(forged, n, period, answered=False)
            for n in range(3, 12):
                stream.tick(clock, n)
        finally:
            stream.end()
            executor.close()
    assert [(p.tick, p.index) for p in stream.poses] == [(n, n) for n in range(12)]
    assert stream.service.stats.finished and stream.service.stats.ticks == 12
    assert {why: n for (_, why), n in stream.service.rejects.by_reason.items()} == {
        "stamp-future": 2, "tick-order": 2, "mismatch": 1}
    said = [r.getMessage() for r in caplog.records]
    assert any("clock tick 1000000 ahead of the run's next, 3" in m for m in said)


def test_a_late_join_is_said_and_a_restarted_run_streams_from_the_beginning(zenoh_hub, small_lib, caplog):
    """A replayer joining at tick 7 started at demonstration 0 without a word; a restarted executor (tick 0 again)
    was said to begin "a new run" while the stream went on mid-demonstration: not the run its seed makes."""
    caplog.set_level(logging.WARNING, logger="foresight.replayer")
    caplog.set_level(logging.INFO, logger="shared.transport")
    first = zenoh_hub()
    keys = Keys(first.prefix)
    with open_session(first) as session:
        stream = Stream(zenoh_hub, small_lib, session, keys)
        executor = Presence(session, keys, "executor")
        clock = TypedPublisher(session, keys.clock)
        try:
            stream.start(executor)
            for n in range(7, 10):
                stream.tick(clock, n)
            executor.close()  # the executor ends, another starts: its token goes and comes back
            deadline = time.monotonic() + 10
            while stream_sees_executor(caplog) < 2:
                assert time.monotonic() < deadline, "the replayer never saw the executor go"
                time.sleep(0.01)
            restarted = Presence(session, keys, "executor")
            try:
                for n in range(12):
                    stream.tick(clock, n)
            finally:
                restarted.close()
        finally:
            stream.end()
    assert [(p.tick, p.index) for p in stream.poses] == [(7, 0), (8, 1), (9, 2)] + [(n, n) for n in range(12)]
    assert stream.service.stats.finished and stream.service.rejects.total == 0
    said = [r.getMessage() for r in caplog.records if r.name == "foresight.replayer"]
    assert any("joined the clock at tick 7" in m and "from its beginning" in m for m in said)
    assert any("clock restarted at tick 0 after tick 9" in m and "starts over" in m for m in said)


def stream_sees_executor(caplog) -> int:
    """How many times the replayer's presence said the executor appeared or disappeared."""
    return sum(r.getMessage().startswith("replayer: peer executor ") for r in caplog.records)
