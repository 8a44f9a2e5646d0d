"""services.demo_run: one run of the demo's scenario."""

from __future__ import annotations

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
