"""``foresight demo --prepare DIR`` (services/demo_prepare.py) stops at once on SIGINT/SIGTERM, training included.

compose.yaml runs it as its one-shot ``prepare``: it ignored SIGTERM while training the model (a minute), so
``docker compose down`` waited out the 20 s grace and killed it (a review).
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from services import demo_prepare
from services.demo import DemoConfig

REPO = Path(__file__).resolve().parents[2]


def _lines(proc: subprocess.Popen[str]) -> queue.Queue[str | None]:
    """The process's output lines as they come (None at its end)."""
    lines: queue.Queue[str | None] = queue.Queue()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line.rstrip("\n"))
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    return lines


def test_sigterm_while_training_stops_prepare_at_once_and_writes_nothing_half(tmp_path: Path) -> None:
    """SIGTERM to the process alone (as init passes on `docker compose down`'s) while the model is trained: it
    stops within seconds with one line and status 130; no model and no config file are written."""
    out, models = tmp_path / "compose", tmp_path / "models"
    proc = subprocess.Popen([sys.executable, "-m", "tools", "demo", "--prepare", str(out), "--models-dir", str(models)],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"}, start_new_session=True)
    lines = _lines(proc)
    seen: list[str] = []
    try:
        deadline = time.monotonic() + 180
        while not any("training the prediction model" in line for line in seen):
            line = lines.get(timeout=max(deadline - time.monotonic(), 0.1))
            assert line is not None, "\n".join(seen)
            seen.append(line)
        time.sleep(0.5)  # well into the training (a minute with the embedded library)
        proc.send_signal(signal.SIGTERM)
        sent = time.monotonic()
        status = proc.wait(timeout=15)
        stop_s = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    while (line := lines.get(timeout=10)) is not None:
        seen.append(line)
    text = "\n".join(seen)
    assert status == 130 and stop_s < 10, text
    assert not any(line.startswith("foresight demo: prediction model") for line in seen), "trained before the signal"
    assert seen[-1] == (f"foresight demo: interrupted while preparing {out}: its config file was not written and a "
                        "model cut short is not cached; run it again to prepare it"), text
    assert "Traceback" not in text
    assert not (out / "foresight.toml").exists()
    assert not [p.name for p in models.rglob("*") if p.is_file()]  # no model, whole or half, and no temporary file


def test_a_signal_before_the_work_prepares_nothing(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setattr(demo_prepare, "prepare", lambda *a, **k: (_ for _ in ()).throw(AssertionError("prepared")))
    stop = threading.Event()
    stop.set()  # SIGTERM during the demo's imports
    said: list[str] = []
    assert demo_prepare.prepare_or_stop(DemoConfig(), tmp_path, stop, said.append) == 130
    assert len(said) == 1 and said[0].startswith(f"foresight demo: interrupted while preparing {tmp_path}:")


def test_a_signal_after_the_work_leaves_it_done(monkeypatch, tmp_path: Path) -> None:
    stop = threading.Event()
    monkeypatch.setattr(demo_prepare, "prepare", lambda *a, **k: stop.set())  # the work done, then the signal
    said: list[str] = []
    assert demo_prepare.prepare_or_stop(DemoConfig(), tmp_path, stop, said.append) == 0 and said == []
