"""The replayer's Zenoh loop: publish the core's messages in real time or on each ClockTick."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

from shared.config import ZenohConfig
from shared.human_source import HumanPublisher
from shared.library import MotionLibrary
from shared.lockstep_followers import TickOrder, TickQueue
from shared.protocol import ClockTick, DemoMarker, Expectations, HumanPose, Keys, Message, Receipt
from shared.scene import DEFAULT_SCENE
from shared.transport import Presence, RejectCounter, describe, open_session, subscribe

from .core import ReplayerConfig, ReplayerCore, load_replay_library, select_demos, unused_options

__all__ = ["ReplayStats", "ReplayerService", "LINGER_S"]

log = logging.getLogger("foresight.replayer")

NO_TICK_WARN_S = 30.0
"""Seconds without a clock tick (lock-step) after which the replayer says it is waiting, and again each as long."""
LINGER_S = 0.3
"""Seconds the session stays open after the last message so that it is delivered before closing."""


@dataclass
class ReplayStats:
    """What a run published."""

    poses: int = 0
    markers: int = 0
    demos: int = 0
    ticks: int = 0
    finished: bool = False


class ReplayerService:
    """Streams a library's demonstrations over Zenoh.

    Args:
        config: Replayer options.
        zenoh_config: Session options (endpoints, prefix).
        library: The library to stream; default: loaded from ``config`` (see
            :func:`~services.replayer.core.load_replay_library`).
    """

    def __init__(self, config: ReplayerConfig, zenoh_config: ZenohConfig, library: MotionLibrary | None = None) -> None:
        self.config = config
        self.zenoh_config = zenoh_config
        self.library = library if library is not None else load_replay_library(config)
        self.embedded = library is None and config.library is None  # the synthetic library, for config.scene
        self.demos = select_demos(self.library, config)
        self.keys = Keys(zenoh_config.prefix)
        self.stats = ReplayStats()
        self.rejects = RejectCounter("replayer", known_keys=self.keys.data_keys())

    def run(self, stop: threading.Event | None = None) -> ReplayStats:
        """Publish until the selection is streamed (or forever with ``loop``) or ``stop`` is set."""
        stop = stop or threading.Event()
        cfg = self.config
        core = self._new_core()
        with open_session(self.zenoh_config, stop, "replayer") as session:
            human = HumanPublisher(session, self.keys)
            # lock-step: listen to the clock before announcing ourselves, so no tick sent after our
            # liveliness token appears is missed
            ticks, order = TickQueue(), TickOrder()
            receipt = Receipt(Expectations(clock="lockstep"))
            clock_sub = (subscribe(session, self.keys.clock, ClockTick, ticks.put, self.rejects, receipt)
                         if cfg.mode == "lockstep" else None)

            def on_peer(peer: str, appeared: bool) -> None:  # the executor gone: its next tick may start a new run
                if peer == "executor" and not appeared:
                    order.executor_gone()

            presence = Presence(session, self.keys, "replayer", on_change=on_peer, stop_with=cfg.stop_with, stop=stop)
            total = core.total_poses
            # the embedded library's reaches are for one scene's cups: said, as a model's scene is
            scene = f", scene {cfg.scene or DEFAULT_SCENE}" if self.embedded else ""
            log.info("replayer: %d demonstrations selected from %s%s (%s poses), mode %s, session %s",
                     len(self.demos), self.library.source, scene, "endless" if total is None else total, cfg.mode,
                     describe(session)["zid"])
            for line in unused_options(cfg):
                log.warning("replayer: %s", line)
            try:
                if clock_sub is not None:
                    core = self._run_lockstep(ticks, order, core, human, stop, presence)
                else:
                    presence.wait_for(cfg.wait_for, cfg.wait_timeout, stop)
                    self._run_realtime(core, human, stop)
                self.stats.finished = core.done
                if core.done:
                    stop.wait(LINGER_S)
            finally:
                presence.close()
                if clock_sub is not None:
                    clock_sub.undeclare()
        log.info("replayer: %s after %d demonstrations, %d poses, %d ticks, rejected: %s",
                 "finished" if self.stats.finished else "stopped", self.stats.demos, self.stats.poses,
                 self.stats.ticks, self.rejects.summary())
        return self.stats

    # ------------------------------------------------------------------------------------------

    def _publish(self, msgs: list[Message], human: HumanPublisher) -> None:
        for m in msgs:
            assert isinstance(m, HumanPose | DemoMarker)
            human.put(m)
            if isinstance(m, DemoMarker) and m.event == "start":
                log.info("replayer: demo %d start: %s (class %d, %s), %d samples", m.demo_id, m.class_name,
                         m.true_class, self._source(m), m.n_samples)
        self.stats.poses, self.stats.markers, self.stats.demos = human.poses, human.markers, human.starts

    def _source(self, m: DemoMarker) -> str:
        d = self.demos[m.demo_id % len(self.demos)]
        return d.source

    def _run_realtime(self, core: ReplayerCore, human: HumanPublisher, stop: threading.Event) -> None:
        period = 1.0 / self.config.rate_hz
        next_t = time.monotonic()
        while not stop.is_set() and not core.done:
            self._publish(core.step(1, stamp=time.time()), human)
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                stop.wait(delay)
            elif delay < -1.0:  # fell far behind (suspended?): do not burst to catch up
                next_t = time.monotonic()

    def _new_core(self) -> ReplayerCore:
        """The schedule from the selection's beginning."""
        return ReplayerCore(self.demos, loop=self.config.loop, max_demos=self.config.max_demos)

    def _run_lockstep(self, ticks: TickQueue, order: TickOrder, core: ReplayerCore, human: HumanPublisher,
                      stop: threading.Event, presence: Presence) -> ReplayerCore:
        """Publish each accepted tick's poses until the stream ends or ``stop``; returns the core last used.

        A tick :class:`TickOrder` refuses is counted and said by the reject counter (a forged or stray tick); tick 0
        of a new run (the executor left and came back) starts the stream over, so that the new run is the one its
        seed makes.
        """
        n = self.config.samples_per_tick
        last = time.monotonic()  # the start, then the last tick: a replayer with no clock said nothing for ever
        while not stop.is_set() and not core.done:
            tick = ticks.get(timeout=0.1)
            if tick is None:
                if time.monotonic() - last >= NO_TICK_WARN_S:
                    if presence.is_alive("executor"):  # up, waiting for a service (a planner compiling): no fault
                        log.info("replayer: no clock tick on %s for %g s; the executor is up: it ticks once the "
                                 "services it waits for are (a planner compiles for up to a minute on a first "
                                 "start)", self.keys.clock, NO_TICK_WARN_S)
                    else:
                        log.warning("replayer: no clock tick on %s for %g s; in lock-step it publishes a pose only "
                                    "when the executor ticks (is one running, with prefix %r?)", self.keys.clock,
                                    NO_TICK_WARN_S, self.keys.prefix)
                    last = time.monotonic()
                continue
            last = time.monotonic()
            verdict = order.accept(tick.tick, tick.period)
            if not verdict.take:
                self.rejects.reject(self.keys.clock, verdict.note, verdict.reason)
                continue
            if verdict.note:
                log.warning("replayer: %s", verdict.note)
            if verdict.new_run:
                core = self._new_core()
            self.stats.ticks += 1
            self._publish(core.step(n, stamp=tick.stamp, tick=tick.tick, dt=tick.period / n), human)
        return core
