"""ExecutorService: a bug while handling a valid message is counted and said once, never raised into Zenoh."""

from __future__ import annotations

import logging
import time

from services.executor.core import ExecutorConfig
from services.executor.service import ExecutorService
from shared.config import ZenohConfig
from shared.protocol import DemoMarker, encode

from .conftest import SCENE


def test_a_bug_handling_a_valid_message_is_counted_not_raised_into_zenohs_thread(pr2, caplog) -> None:
    """Before, the dispatch sat outside the try: the exception reached Zenoh's callback thread, uncounted."""
    service = ExecutorService(ExecutorConfig(mode="realtime"), ZenohConfig(), robot=pr2, human=(None, None),
                              scene=SCENE)

    def broken(*args, **kwargs) -> None:
        raise RuntimeError("a bug in the core")

    service.core.note_demonstration = broken
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        for demo in range(3):
            marker = DemoMarker(stamp=time.time(), tick=-1, demo_id=demo, event="start", true_class=0, class_name="a",
                                n_samples=5)
            service._on_sample(service.keys.demo, encode(marker), "replayer")  # as Zenoh's callback would
    assert service.rejects.by_reason == {(service.keys.demo, "handler"): 3}
    traced = [r for r in caplog.records if r.exc_info]
    assert len(traced) == 1 and "handling a DemoMarker on" in traced[0].getMessage()


def test_junk_keys_arriving_first_leave_the_plan_key_counted_on_its_own(pr2) -> None:
    """The executor logs ``<prefix>/**``: before, 32 made-up keys first sent a plan's rejects to ``(other keys)``."""
    service = ExecutorService(ExecutorConfig(mode="realtime"), ZenohConfig(), robot=pr2, human=(None, None),
                              scene=SCENE)
    for i in range(40):
        service._on_sample(f"{service.keys.prefix}/junk/{i}", b"\x01", "replayer")
    service._on_sample(service.keys.plan, b"not msgpack", "planner")
    assert service.rejects.counts[service.keys.plan] == 1
