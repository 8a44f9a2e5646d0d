"""The Makefile's ``make demo``: Ctrl-C is the demo's normal end, not make's error; a failure still fails."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# `foresight demo` as it ends: on SIGINT it stops its services and exits 130; else with the status it is given
FAKE_DEMO = f"""#!{sys.executable}
import os, signal, sys, time
signal.signal(signal.SIGINT, lambda *a: sys.exit(130))
print("ready", flush=True)
if "FAKE_STATUS" in os.environ:
    sys.exit(int(os.environ["FAKE_STATUS"]))
time.sleep(60)
"""


def _make_demo(tmp_path: Path, status: int | None) -> tuple[subprocess.Popen[str], str]:
    """``make demo`` with a venv whose ``foresight`` is :data:`FAKE_DEMO`, in a process group of its own."""
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").symlink_to(sys.executable)
    (venv / ".installed").touch()  # newer than pyproject.toml: nothing to install
    fake = venv / "bin" / "foresight"
    fake.write_text(FAKE_DEMO)
    fake.chmod(0o755)
    env = {**os.environ, **({} if status is None else {"FAKE_STATUS": str(status)})}
    proc = subprocess.Popen(["make", "-s", "-C", str(REPO), "demo", f"VENV={venv}"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=env,
                            start_new_session=True)
    assert proc.stdout is not None
    return proc, proc.stdout.readline()


@pytest.fixture
def group_killer():
    """Kill the started process groups that are still running at the end."""
    procs: list[subprocess.Popen[str]] = []
    yield procs.append
    for proc in procs:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)


pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs make")


def test_ctrl_c_of_make_demo_is_no_make_error(tmp_path: Path, group_killer) -> None:
    """A terminal's Ctrl-C (SIGINT to make, its shell and the demo): the demo stopped cleanly, and make said
    "make: *** [Makefile:30: demo] Error 130" after it (a new user's first hour)."""
    proc, first = _make_demo(tmp_path, None)
    group_killer(proc)
    assert first == "ready\n"
    os.killpg(proc.pid, signal.SIGINT)
    rest = proc.communicate(timeout=30)[0]
    assert rest == "" and proc.returncode in (0, -signal.SIGINT), rest  # make ends as its terminal told it


@pytest.mark.parametrize("status, said", [(0, ""), (130, ""), (1, "] Error 1"), (2, "] Error 2")])
def test_make_demo_fails_with_the_demos_failure(status: int, said: str, tmp_path: Path, group_killer) -> None:
    proc, first = _make_demo(tmp_path, status)
    group_killer(proc)
    rest = proc.communicate(timeout=30)[0]
    assert first == "ready\n" and (said in rest if said else rest == ""), rest
    assert proc.returncode == (2 if said else 0)
