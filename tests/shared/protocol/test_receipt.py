"""Receipt: decode + values + ticks and sequence numbers monotonic per sender; RejectCounter per key and reason."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest

from shared.protocol import (
    ClockTick,
    DemoMarker,
    Expectations,
    HumanPose,
    Plan,
    ProtocolError,
    Receipt,
    RobotState,
    SenderOrder,
    encode,
)
from shared.protocol import receipt as receipt_module
from shared.rejects import RejectCounter

F = np.array([0.0, 0.0, 1.0] + [0.1] * 9)


def pose(tick: int, demo: int, index: int) -> HumanPose:
    return HumanPose(stamp=0.2 * max(tick, 0), tick=tick, tick_last=True, demo_id=demo, index=index, features=F)


def order_refused(order: SenderOrder, key: str, sender: str, msg, reason: str) -> None:
    with pytest.raises(ProtocolError) as info:
        order.check(key, sender, msg)
    assert info.value.reason == reason


def test_ticks_never_decrease_per_sender():
    order = SenderOrder()
    order.check("k", "a", pose(3, 0, 0))
    order.check("k", "a", pose(3, 0, 1))
    order_refused(order, "k", "a", pose(2, 0, 2), "tick-order")
    order.check("k", "b", pose(2, 0, 0))  # another sender has its own record
    order.check("other", "a", pose(1, 0, 0))  # and another key
    order.check("k", "a", pose(4, 0, 2))  # the refused one changed nothing


def test_tick_zero_starts_a_new_run():
    order = SenderOrder()
    order.check("k", "a", pose(7, 0, 30))
    order.check("k", "a", pose(0, 0, 0))  # a new lock-step run: the sender's record restarts
    order_refused(order, "k", "a", pose(0, 0, 0), "sequence-order")


def test_clock_ticks_strictly_increase():
    order = SenderOrder()
    order.check("c", "x", ClockTick(stamp=0.2, tick=1, period=0.2))
    order_refused(order, "c", "x", ClockTick(stamp=0.2, tick=1, period=0.2), "tick-order")
    order.check("c", "x", ClockTick(stamp=0.4, tick=2, period=0.2))


def test_pose_sequence_strictly_increases_real_time():
    order = SenderOrder()
    order.check("p", "r", pose(-1, 0, 0))
    order.check("p", "r", pose(-1, 0, 1))
    order_refused(order, "p", "r", pose(-1, 0, 1), "sequence-order")
    order_refused(order, "p", "r", pose(-1, 0, 0), "sequence-order")
    order.check("p", "r", pose(-1, 1, 0))  # the next demonstration starts at index 0
    order_refused(order, "p", "r", pose(-1, 0, 5), "sequence-order")


def test_marker_and_plan_sequences():
    order = SenderOrder()

    def marker(demo: int, event: str) -> DemoMarker:
        return DemoMarker(stamp=1.0, tick=-1, demo_id=demo, event=event, true_class=0, class_name="c", n_samples=1)

    order.check("d", "r", marker(0, "start"))
    order.check("d", "r", marker(0, "end"))
    order_refused(order, "d", "r", marker(0, "start"), "sequence-order")
    order.check("d", "r", marker(1, "start"))
    order.check("d", "r", marker(1, "lost"))  # a reach the tracker lost: after its start
    order_refused(order, "d", "r", marker(1, "end"), "sequence-order")  # a lost reach has no end
    order.check("d", "r", marker(2, "start"))
    order.check("d", "r", marker(2, "end"))
    order.check("d", "r", marker(2, "lost"))  # the person gone from where it showed them (refused before)
    order_refused(order, "d", "r", marker(2, "lost"), "sequence-order")  # once
    order.check("d", "r", marker(3, "start"))
    plan = Plan(stamp=1.0, tick=-1, step=4, goal_names=["g"], joint_names=["a"], dt=0.1, chosen=0, planning_ms=1.0,
                occupancy_tick=-1, occupancy_index=-1, trajectories=np.zeros((1, 2, 1), np.float32),
                cost_smoothness=np.zeros(1), cost_obstacle=np.zeros(1), cost_human=np.zeros(1),
                cost_total=np.zeros(1), valid=np.ones(1, bool))
    order.check("plan", "p", plan)
    order_refused(order, "plan", "p", dataclasses.replace(plan, step=3), "sequence-order")


def test_sender_memory_is_bounded(monkeypatch):
    monkeypatch.setattr(receipt_module, "MAX_SENDERS", 4)
    order = SenderOrder()
    for i in range(50):
        order.check("k", f"s{i}", pose(5, 0, 0))
    assert len(order) == 4


def test_made_up_sender_ids_cannot_push_out_a_sender_that_is_talking(monkeypatch):
    """The oldest record was evicted: 4 fresh ids between two of a sender's messages reset its order."""
    monkeypatch.setattr(receipt_module, "MAX_SENDERS", 4)
    order = SenderOrder()
    order.check("k", "real", pose(5, 0, 7))
    for i in range(4):  # one made-up id between two of the real sender's messages
        order.check("k", f"fake{i}", pose(5, 0, 0))
        if i < 3:
            order.check("k", "real", pose(5, 0, 8 + i))  # talking: its record stays the most recent
    order_refused(order, "k", "real", pose(5, 0, 7), "sequence-order")  # an old pose is still refused


def test_receipt_decodes_checks_values_then_order():
    receipt = Receipt(Expectations(clock="lockstep", period_s=0.2))
    st = RobotState(stamp=0.4, tick=1, joint_names=["a"], goal=-1, reached=False, holding=True, reason="x",
                    q=np.zeros(1), qd=np.zeros(1))
    assert receipt.accept("s", encode(st), RobotState, "exe").tick == 1
    with pytest.raises(ProtocolError) as info:
        receipt.accept("s", b"\xc1", RobotState, "exe")
    assert info.value.reason == "malformed"
    with pytest.raises(ProtocolError) as info:
        receipt.accept("s", encode(dataclasses.replace(st, stamp=9.0)), RobotState, "exe")
    assert info.value.reason == "stamp-future"
    receipt.accept("s", encode(dataclasses.replace(st, tick=2, stamp=0.5)), RobotState, "exe")
    with pytest.raises(ProtocolError) as info:
        receipt.accept("s", encode(st), RobotState, "exe")
    assert info.value.reason == "tick-order"
    assert Receipt(order=False).order is None


def test_reject_counter_counts_per_key_and_reason_and_rate_limits(caplog):
    t = [0.0]
    counter = RejectCounter("svc", log_period_s=1.0, clock=lambda: t[0])
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        for _ in range(500):
            counter.reject("k/a", ProtocolError("RobotState.q: far out", "joint-limits"))
        counter.reject("k/a", ValueError("no reason attribute"))
        counter.reject("k/b", "plain text", reason="stamp-past")
        t[0] = 1.5
        counter.reject("k/a", ProtocolError("x", "velocity"))
    assert counter.by_reason == {("k/a", "joint-limits"): 500, ("k/a", "malformed"): 1, ("k/a", "velocity"): 1,
                                 ("k/b", "stamp-past"): 1}
    assert counter.counts == {"k/a": 502, "k/b": 1} and counter.total == 503
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 4, lines  # one per key per second and the first of each reason, not one per message
    assert "(malformed): no reason attribute [501 so far: joint-limits 500, malformed 1]" in lines[1]
    assert "502 so far: joint-limits 500, malformed 1, velocity 1" in lines[-1]
    assert counter.summary() == "k/a: joint-limits 500, malformed 1, velocity 1; k/b: stamp-past 1"
    assert RejectCounter("x").summary() == "none"
