"""What a demo run prints as it goes (services.demo_lines, as services.demo_run uses it)."""

from __future__ import annotations

import threading
from pathlib import Path

from services import demo_lines


def test_a_reader_that_leaves_ends_the_printing_not_the_run(monkeypatch) -> None:
    """`foresight demo | head -3`: "Exception in thread demo-lines: ... BrokenPipeError", a traceback mid-run."""
    raised: list[BaseException] = []
    monkeypatch.setattr(threading, "excepthook", lambda args: raised.append(args.exc_value))
    tried: list[str] = []

    def head(line: str) -> None:  # a pipe whose reader exited after three lines
        tried.append(line)
        if len(tried) > 3:
            raise BrokenPipeError(32, "Broken pipe")

    with demo_lines.Lines(head) as say:
        for i in range(10):
            say(f"row {i}")
    assert raised == [] and tried == [f"row {i}" for i in range(4)]  # nothing printed once the reader is gone


def test_an_empty_log_is_said_unreadable_in_the_runs_last_line(tmp_path: Path) -> None:
    """A full disk as the executor opened its log left it empty: the run ended in "error: ...mcap: not an MCAP file
    (empty)", status 2, and its outcome was not printed (a review)."""
    mcap = tmp_path / "run.mcap"
    mcap.write_bytes(b"")
    phrase = demo_lines.log_phrase(mcap, "foresight/plan", 3, 3)
    assert phrase == f"log {mcap}: unreadable, no message in it ({mcap}: not an MCAP file (empty))"
