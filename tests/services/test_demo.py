"""The interim ``foresight demo``: process management and an end-to-end run with a small library."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from services.demo import DemoConfig, ServiceProcess, StreamMonitor, main, run_demo
from shared.library import Demonstration, MotionLibrary, save_library
from shared.protocol import DemoMarker, HumanPose
from shared.runtime import UserError


def small_npz(path: Path) -> Path:
    rng = np.random.default_rng(0)
    demos = []
    for m in range(2):
        for k in range(3):
            f = np.column_stack([np.full(15, 1.0 + m), np.full(15, 1.0 + k), np.full(15, 0.9),
                                 0.1 * rng.normal(size=(15, 9))])
            demos.append(Demonstration(m, f"c{m}", k, f, f"t#{m}.{k}"))
    save_library(MotionLibrary(["c0", "c1"], demos, [], "small"), path)
    return path


def test_stream_monitor_lines():
    t = [0.0]
    mon = StreamMonitor(clock=lambda: t[0])
    mon.on_message(DemoMarker(stamp=0, tick=-1, demo_id=0, event="start", true_class=1, class_name="c1", n_samples=3))
    for i in range(3):
        t[0] = 0.1 * i
        mon.on_message(HumanPose(stamp=0, tick=-1, tick_last=True, demo_id=0, index=i, features=np.zeros(12)))
    assert mon.progress() == "demo 0: 3/3 poses, 10.0 Hz"
    mon.on_message(DemoMarker(stamp=0, tick=-1, demo_id=0, event="end", true_class=1, class_name="c1", n_samples=3))
    assert mon.take_lines() == ["demo 0: start, class 1 (c1), 3 samples", "demo 0: end, received 3/3 poses at 10.0 Hz"]
    assert mon.finished == 1 and mon.progress() is None and mon.take_lines() == []


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


def test_demo_end_to_end(tmp_path):
    lines: list[str] = []
    cfg = DemoConfig(library=small_npz(tmp_path / "lib.npz"), demos=3, rate_hz=200.0, run_dir=tmp_path / "run",
                     timeout=60.0)
    assert run_demo(cfg, threading.Event(), out=lines.append) == 0, "\n".join(lines)
    text = "\n".join(lines)
    assert "2 classes, 6 demonstrations" in text
    for d in range(3):
        assert f"demo {d}: end, received 15/15 poses" in text
    assert "3 demonstrations, 45 poses received; replayer exit status 0" in text
    assert "predictor:" in text and "planner:" in text and "executor:" in text
    assert (tmp_path / "run" / "replayer.log").read_text().count("start:") == 3


def test_demo_bad_input_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--library", str(tmp_path / "missing"), "--run-dir", str(tmp_path)])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "missing' not found" in err
    with pytest.raises(SystemExit):
        main(["--demos", "0"])
    assert "demo.demos: must be >= 1" in capsys.readouterr().err
