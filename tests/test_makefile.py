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


def _fake_python(path: Path, body: str) -> Path:
    """An executable ``python3`` for ``make setup``: ``body`` is a shell script's, then the real Python's."""
    path.write_text(f"#!/bin/sh\n{body}\nexec {sys.executable} \"$@\"\n")
    path.chmod(0o755)
    return path


def _make_setup(tmp_path: Path, python: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["make", "-s", "-C", str(REPO), "setup", f"VENV={tmp_path / 'venv'}", f"PYTHON={python}"],
                          capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=60)


def test_setup_on_python_3_10_stops_before_installing_anything(tmp_path: Path) -> None:
    """A 3.10 venv downloaded torch (4.6 GB), then failed on requires-python, and stayed for every later make."""
    old = _fake_python(tmp_path / "python3", 'case "$1" in -V) echo "Python 3.10.13"; exit 0;; -c) exit 1;; esac\n'
                                             "exit 99")
    done = _make_setup(tmp_path, old)
    assert done.returncode != 0 and not (tmp_path / "venv").exists()
    assert f"make setup: Foresight needs Python 3.11+, and {old} is Python 3.10.13; run make PYTHON=python3.11" \
        in done.stdout, done.stdout + done.stderr


def test_a_venv_python_could_not_finish_is_removed(tmp_path: Path) -> None:
    """Debian without python3-venv: the half-made venv had no pip, and every later make failed on it."""
    debian = _fake_python(tmp_path / "python3", f'if [ "$1" = "-m" ] && [ "$2" = venv ]; then mkdir -p "$3/bin"; '
                                               f'ln -s {sys.executable} "$3/bin/python"; '
                                               'echo "The virtual environment was not created successfully because '
                                               'ensurepip is not available." >&2; exit 1; fi')
    done = _make_setup(tmp_path, debian)
    assert done.returncode != 0 and not (tmp_path / "venv").exists()
    assert "apt install python3-venv), and the half-made" in done.stdout, done.stdout + done.stderr
