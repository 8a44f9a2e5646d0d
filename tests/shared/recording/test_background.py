"""BackgroundWorker: order, drops when full, errors counted, close drains."""

from __future__ import annotations

import threading

import pytest

from shared.recording.background import BackgroundWorker


def test_items_run_in_order_and_close_drains_them() -> None:
    seen: list[int] = []
    w = BackgroundWorker(seen.append, "t", max_pending=100)
    for i in range(50):
        assert w.submit(i)
    assert w.close()
    assert seen == list(range(50)) and w.done == 50 and w.dropped == 0
    assert not w.submit(99) and w.dropped == 1  # closed: refused, counted
    assert w.close()  # idempotent


def test_a_full_queue_drops_instead_of_waiting_and_errors_are_counted() -> None:
    entered, release = threading.Event(), threading.Event()
    seen: list[int] = []

    def work(i: int) -> None:
        if i == 0:
            entered.set()
            release.wait(10)
        if i == 2:
            raise RuntimeError("bad item")
        seen.append(i)

    w = BackgroundWorker(work, "t", max_pending=2)
    assert w.submit(0) and entered.wait(10)  # item 0 is being worked on: the queue is empty
    assert w.submit(1) and w.submit(2)
    assert not w.submit(3)  # two already wait: dropped at once, the caller never blocks
    release.set()
    assert w.close()
    assert seen == [0, 1] and w.errors == 1 and w.dropped == 1 and w.done == 3


def test_max_pending_must_be_positive() -> None:
    with pytest.raises(ValueError, match="max_pending"):
        BackgroundWorker(print, "t", max_pending=0)
