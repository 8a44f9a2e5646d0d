"""Service processes: early exit reported, bounded stop."""

from __future__ import annotations

import sys
import time

import pytest

from services.processes import ServiceProcess
from shared.runtime import UserError


def test_service_process_reports_early_exit(tmp_path):
    proc = ServiceProcess("replayer", "services.replayer", ["--library", str(tmp_path / "none")], tmp_path / "r.log")
    proc.start()
    with pytest.raises(UserError, match=r"replayer exited with status 2: .*none' not found"):
        proc.wait_alive(lambda name: False, timeout=30.0)
    assert proc.stop(timeout=5.0) == 2


def test_service_process_stop_is_bounded(tmp_path):
    # a process that ignores SIGTERM is killed after the timeout
    script = tmp_path / "stubborn.py"
    script.write_text("import signal, time\nsignal.signal(signal.SIGTERM, signal.SIG_IGN)\nprint('up', flush=True)\n"
                      "time.sleep(60)\n")
    proc = ServiceProcess("stubborn", "stubborn", [], tmp_path / "s.log", env={"PYTHONPATH": str(tmp_path)})
    proc.start()
    deadline = time.monotonic() + 20
    while "up" not in proc.tail() and time.monotonic() < deadline:
        time.sleep(0.05)
    t0 = time.monotonic()
    code = proc.stop(timeout=0.5)
    assert code is not None and code < 0 and not proc.running
    assert time.monotonic() - t0 < 10
    assert proc.command[:3] == [sys.executable, "-m", "stubborn"]


def test_a_restart_keeps_the_log_of_the_run_that_ended(tmp_path):
    """The supervisor's restart truncated the log: the crash's traceback, the one thing to read, was lost."""
    (tmp_path / "crashy.py").write_text("import os, sys\nif not os.path.exists(sys.argv[1]):\n"
                                        "    open(sys.argv[1], 'w').close()\n    raise RuntimeError('the cause')\n"
                                        "print('second start: fine')\n")
    proc = ServiceProcess("planner", "crashy", [str(tmp_path / "flag")], tmp_path / "planner.log",
                          env={"PYTHONPATH": str(tmp_path)})
    proc.start()
    proc.proc.wait(30)
    proc.start()
    proc.proc.wait(30)
    text = (tmp_path / "planner.log").read_text()
    assert "RuntimeError: the cause" in text and "second start: fine" in text
    assert text.index("the cause") < text.index("planner started again (the run above exited with status 1)") \
        < text.index("second start: fine")
