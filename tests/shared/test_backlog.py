"""The bounded FIFO between Zenoh's callbacks and a service's worker."""

from __future__ import annotations

import threading
import time

import pytest

from shared.backlog import Backlog


def test_backlog_keeps_order_drops_the_oldest_beyond_its_limit_and_counts():
    b: Backlog[int] = Backlog(3)
    assert b.take_all(0.01) == []
    for i in range(5):
        b.put(i)
    assert len(b) == 3 and b.dropped == 2 and b.peak == 3
    assert b.take_all(0.01) == [2, 3, 4]
    assert len(b) == 0
    with pytest.raises(ValueError, match="limit"):
        Backlog(0)


def test_backlog_wakes_a_waiting_consumer():
    b: Backlog[str] = Backlog(10)
    got: list[list[str]] = []
    th = threading.Thread(target=lambda: got.append(b.take_all(5.0)))
    th.start()
    time.sleep(0.05)
    b.put("x")
    th.join(5.0)
    assert got == [["x"]]
