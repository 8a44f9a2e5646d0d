"""services.demo_run: one run of the demo's scenario."""

from __future__ import annotations

import sys
import threading
from pathlib import Path

import pytest

from services import demo_run
from services.demo import DemoConfig


def test_a_ctrl_c_before_the_run_is_prepared_prepares_nothing(monkeypatch, tmp_path: Path) -> None:
    """A review: Ctrl-C during the demo's imports set the stop, and the run went on to load (or train, a minute)
    its model before it said it was interrupted (6.6 s with a cached model)."""
    monkeypatch.setattr(demo_run, "prepare_inputs", lambda *a, **k: pytest.fail("prepared after the Ctrl-C"))
    stop = threading.Event()
    stop.set()
    said: list[str] = []
    status, record = demo_run.run_once(DemoConfig(run_dir=str(tmp_path)), "prediction", stop, said.append)
    assert (status, record) == (130, None)
    assert said == ["foresight demo: interrupted before the run was prepared; no service had started, nothing was "
                    "recorded"]


def test_the_rows_never_wait_for_the_terminal_and_keep_their_order() -> None:
    """The table's rows were printed from a Zenoh callback: `foresight demo | less` left unscrolled blocked it, and
    with it the services' publishers (they block on congestion). The caller must come back at once, whatever the
    terminal does, and every line must come out, in order, by the end."""
    gate, printed = threading.Event(), []

    def terminal(line: str) -> None:  # a terminal nobody reads, until the gate opens
        gate.wait(30)
        printed.append(line)

    with demo_run._Lines(terminal) as say:
        for i in range(200):
            say(f"row {i}")  # returns although the terminal reads nothing: else this test would hang here
        assert printed == []
        gate.set()
    assert printed == [f"row {i}" for i in range(200)]


def test_a_ctrl_c_while_training_ends_its_progress_bar_before_saying_so(monkeypatch, tmp_path: Path, capsys) -> None:
    """The training's bar was closed only when the loop Ctrl-C broke out of was collected: after the "interrupted
    while preparing" line, a half bar was the last thing on the terminal (a new user's first `make demo`)."""
    from shared.progress import progress

    def fit(n: int) -> int:
        if n == 2:
            raise KeyboardInterrupt
        return n

    def training(*args: object) -> None:  # as train_model's loops: a comprehension's frame holds the bar (it stays)
        [fit(n) for n in progress(range(4), desc="GMM per class", unit="class")]

    monkeypatch.setattr(demo_run, "prepare_inputs", training)
    say = lambda line: print(line, file=sys.stderr)  # noqa: E731 (the bar's stream: their order is seen)
    status, _ = demo_run.run_once(DemoConfig(run_dir=str(tmp_path)), "prediction", threading.Event(), say)
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 130 and lines[-1].startswith("foresight demo: interrupted while preparing the run"), lines
    assert lines[-2].startswith("GMM per class:") and "| 2/4 [" in lines[-2], lines
