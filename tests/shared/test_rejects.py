"""RejectCounter: refused messages counted per key and reason, logged rate-limited, never on a forged line."""

from __future__ import annotations

import logging

from shared.protocol import ProtocolError
from shared.rejects import RejectCounter


def test_a_bug_repeated_by_a_peer_logs_its_traceback_once_per_key_and_counts_every_message(caplog) -> None:
    now = [0.0]
    rejects = RejectCounter("svc", log_period_s=1.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        for i in range(20):
            now[0] = float(i)  # past the rate limit every time: only the traceback is held back
            rejects.unexpected("fs/pose", SyntaxError("a decoder bug"), "decoding a message")
        rejects.unexpected("fs/plan", SyntaxError("a decoder bug"), "decoding a message")
    traced = [r for r in caplog.records if r.exc_info]
    assert [r.getMessage() for r in traced] == [
        "svc: decoding a message on fs/pose failed unexpectedly (this traceback once per key; later ones are counted)",
        "svc: decoding a message on fs/plan failed unexpectedly (this traceback once per key; later ones are counted)"]
    assert rejects.counts == {"fs/pose": 20, "fs/plan": 1}
    # the first said once (its traceback), not twice; filed under this process's bug, not the sender's "malformed"
    assert sum("rejected a message on fs/pose" in r.getMessage() for r in caplog.records) == 19
    assert not any("rejected a message on fs/plan" in r.getMessage() for r in caplog.records)
    assert rejects.by_reason == {("fs/pose", "handler"): 20, ("fs/plan", "handler"): 1}


def test_a_peers_text_cannot_start_a_log_line_of_its_own(caplog) -> None:
    rejects = RejectCounter("svc")
    forged = "x\n2030-01-01 00:00:00,000 services.executor INFO executor: run finished cleanly\r"
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        rejects.reject("fs/pose", ProtocolError(f"HumanPose: unknown field(s) {forged}"))
    (line,) = [r.getMessage() for r in caplog.records]
    assert "\n" not in line and "\r" not in line and "x\\n2030-01-01" in line and "cleanly\\r" in line


def test_the_first_of_each_reason_on_a_key_is_logged_at_once_the_rest_rate_limited(caplog) -> None:
    """Before, four faults of four kinds within a second logged the first only: a robot on another ROS 2
    distribution (a type hash of its own) was never named while garbled samples came first."""
    rejects = RejectCounter("simrobot", log_period_s=1.0, clock=lambda: 0.0)
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        for why in ("attachment", "type", "malformed", "attachment", "type", "malformed"):
            rejects.reject("/arm/joint_trajectory", f"{why} fault", reason=why)
    lines = [r.getMessage() for r in caplog.records]
    assert [line.split("(")[1].split(")")[0] for line in lines] == ["attachment", "type", "malformed"]
    assert lines[-1].endswith("[3 so far: attachment 1, malformed 1, type 1]")
    assert rejects.summary() == "/arm/joint_trajectory: attachment 2, malformed 2, type 2"

