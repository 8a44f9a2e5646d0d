"""RejectCounter: refused messages counted per key and reason, logged rate-limited, never on a forged line."""

from __future__ import annotations

import logging

from shared.protocol import ProtocolError
from shared.rejects import OTHER_KEYS, RejectCounter


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



def test_a_peers_key_cannot_start_a_log_line_of_its_own(caplog) -> None:
    """Before, the key went into the line raw: a key with a line break forged a line of its own."""
    rejects = RejectCounter("svc")
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        rejects.reject("fs/a\nWARNING forged\x1b[31m", ProtocolError("bad"))
        rejects.unexpected("fs/b\r\nERROR forged", ValueError("bug"), "checking a message")
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and not any(c in line for line in lines for c in "\n\r\x1b")
    assert "fs/a\\nWARNING forged\\x1b[31m" in lines[0] and "fs/b\\r\\nERROR forged" in lines[1]
    assert rejects.counts == {"fs/a\nWARNING forged\x1b[31m": 1, "fs/b\r\nERROR forged": 1}  # counted as they came
    assert rejects.summary() == "fs/a\\nWARNING forged\\x1b[31m: malformed 1; fs/b\\r\\nERROR forged: handler 1"


def test_a_flood_of_distinct_keys_is_counted_in_one_bucket_and_logged_rate_limited(caplog) -> None:
    """Before, 2000 distinct keys kept 2000 records and logged 2000 lines at once."""
    now = [0.0]
    rejects = RejectCounter("svc", log_period_s=1.0, clock=lambda: now[0], max_keys=4)
    with caplog.at_level(logging.WARNING, logger="foresight.rejects"):
        for i in range(2000):
            rejects.reject(f"fs/junk/{i}", ProtocolError("bad"))
            rejects.unexpected(f"fs/bug/{i}", ValueError("bug"), "checking a message")
        now[0] = 1.5
        rejects.reject("fs/junk/late", ProtocolError("bad", "too-large"))
        rejects.reject("fs/junk/later", ProtocolError("bad", "too-large"))
    lines = [r.getMessage() for r in caplog.records]
    # 4 keys one by one (2 of them a traceback), then the bucket: its first malformed and its traceback at once,
    # then its new reason at 1.5 s; nothing else
    assert len(lines) == 4 + 2 + 1 and sum(bool(r.exc_info) for r in caplog.records) == 3
    assert lines[-1].startswith("svc: rejected a message on fs/junk/late (too-large): bad [3997 so far on "
                                f"other keys past the first 4, counted as {OTHER_KEYS}: handler 1998, malformed 1998, "
                                "too-large 1]")
    assert rejects.total == 4002 and len(rejects.by_reason) == 4 + 3  # every message counted, in bounded records
    assert rejects.counts[OTHER_KEYS] == 3998 and rejects.counts["fs/junk/0"] == 1
    assert rejects.summary().startswith(f"{OTHER_KEYS}: handler 1998, malformed 1998, too-large 2; fs/bug/0")


def test_the_contracts_keys_keep_their_own_count_after_a_flood_of_junk_keys() -> None:
    """Before, junk on the first ``max_keys`` keys pushed a contract key's rejects into the shared bucket."""
    rejects = RejectCounter("svc", max_keys=4, known_keys=["fs/planner/plan"])
    for i in range(10):
        rejects.reject(f"fs/junk/{i}", ProtocolError("bad"))
    rejects.reject("fs/planner/plan", ProtocolError("bad plan", "too-large"))
    assert rejects.counts["fs/planner/plan"] == 1 and rejects.counts[OTHER_KEYS] == 6
    assert rejects.by_reason[("fs/planner/plan", "too-large")] == 1
