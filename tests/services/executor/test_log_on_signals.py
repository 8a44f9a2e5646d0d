"""The executor finalises its MCAP log on SIGTERM/SIGINT and reports a bad option in one line."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from shared.protocol import Keys
from shared.recording.reader import read_log

REPO = Path(__file__).resolve().parents[3]
KEYS = Keys()


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_executor_finalises_its_log_on_signals(tmp_path, sig) -> None:
    path = tmp_path / "svc.mcap"
    cmd = [sys.executable, "-m", "services.executor", "--mode", "realtime", "--steps", "0", "--mcap", str(path),
           "--listen", f"tcp/127.0.0.1:{_free_port()}", "--connect", "", "--state-rate-hz", "20", "--wait-for", ""]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and proc.poll() is None:
            if path.exists() and path.stat().st_size > 0:
                break
            time.sleep(0.05)
        time.sleep(1.0)  # some robot states
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert proc.returncode == 0, err
    assert f"mcap: {path}" in out
    lf = read_log(path)
    assert lf.complete and not lf.error
    counts = {c.topic: c.count for c in lf.channels.values()}
    assert counts[KEYS.robot_state] >= 5
    assert "foresight.rejects" in lf.metadata


def test_executor_bad_option_is_one_line(tmp_path) -> None:
    proc = subprocess.run([sys.executable, "-m", "services.executor", "--stale-limit-s", "-1"], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "python -m services.executor: error: executor.stale_limit_s: must be > 0, got -1.0 (set by --stale-limit-s)"]
