"""services.demo_run: one run of the demo's scenario."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import pytest

from services import demo_lines, demo_run
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

    with demo_lines.Lines(terminal) as say:
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


class _Service(demo_run.ServiceProcess):
    """A service that "starts" at once and writes ``said`` to its log; the executor's start is the person's Ctrl-C."""

    stop_event: threading.Event
    said: list[str]
    waits: list[tuple[str, bool]]

    def start(self) -> _Service:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self.log_path.write_text("stopped while starting\n" if self.name == "planner" else "")  # the executor: empty
        self._log_from, self.alive = 0, True
        if self.name == "executor":
            self.stop_event.set()  # Ctrl-C as the executor still imports: SIGTERM comes before its handlers
        return self

    @property
    def running(self) -> bool:
        return self.alive

    @property
    def returncode(self) -> int | None:
        return None if self.alive else -15

    def wait_alive(self, is_alive, timeout, stop=None) -> bool:  # the line before it is queued, printed in a moment
        deadline = time.monotonic() + (2.0 if self.name == "planner" else 0.0)
        while not any(line.startswith("foresight demo: waiting for the planner") for line in self.said):
            if time.monotonic() > deadline:
                break
            time.sleep(0.01)
        self.waits.append((self.name, any("waiting for the planner" in line for line in self.said)))
        return True

    def stop(self, timeout: float = 5.0, kill_wait: float = 5.0) -> int | None:
        self.alive = False
        return -15


def _start_and_interrupt(monkeypatch, tmp_path: Path) -> tuple[list[str], list[tuple[str, bool]]]:
    """One run whose services are fakes (:class:`_Service`), interrupted as the executor starts."""
    from types import SimpleNamespace

    stop, said, waits = threading.Event(), [], []
    scenario = SimpleNamespace(demo=SimpleNamespace(class_name="blue_cup"), samples_per_tick=1)
    monkeypatch.setattr(demo_run, "prepare_inputs", lambda *a: (scenario, tmp_path / "m.npz", tmp_path / "h.npz"))
    monkeypatch.setattr(_Service, "stop_event", stop, raising=False)
    monkeypatch.setattr(_Service, "said", said, raising=False)
    monkeypatch.setattr(_Service, "waits", waits, raising=False)
    monkeypatch.setattr(demo_run, "ServiceProcess", _Service)
    status, record = demo_run.run_once(DemoConfig(run_dir=str(tmp_path)), "prediction", stop, said.append)
    assert (status, record) == (130, None), said
    return said, waits


def test_the_planners_silent_start_is_said_before_the_demo_waits_for_it(monkeypatch, tmp_path: Path) -> None:
    """A new user's first start went from "predictor up (2.7 s)" to "planner up (50.2 s)" with nothing between."""
    said, waits = _start_and_interrupt(monkeypatch, tmp_path)
    assert ("planner", True) in waits, (waits, said)  # said before the wait, not after it
    (line,) = [ln for ln in said if "waiting for the planner" in ln]
    assert "loads torch and compiles its cost" in line and str(tmp_path / "planner.log") in line, line


def test_a_service_stopped_before_it_wrote_anything_gets_a_line_in_its_log(monkeypatch, tmp_path: Path) -> None:
    """Ctrl-C 2.5 s after "replayer up": the executor, still importing, died of the SIGTERM before its handlers
    existed, and its log was empty beside the planner's "stopped while starting" (a new user's first hour)."""
    _start_and_interrupt(monkeypatch, tmp_path)
    assert (tmp_path / "executor.log").read_text() == (
        "executor was killed (SIGTERM): stopped by foresight demo before it had started (SIGTERM while it was still "
        "importing, before its signal handlers)\n")
    assert (tmp_path / "planner.log").read_text() == "stopped while starting\n"  # it said why itself
