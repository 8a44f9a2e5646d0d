"""Shared fixtures: loopback Zenoh endpoints (scouting off) and the reference-material location."""

from __future__ import annotations

import select
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest

from services.processes import free_port
from shared.config import ZenohConfig
from shared.native_threads import limit_blas_threads

limit_blas_threads()  # as every foresight process does (shared/native_threads.py)

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"  # read-only reference material beside the clone
PAPER_LIBRARY = SHARED / "data" / "paper-library"
REFERENCE = SHARED / "reference"


@pytest.fixture
def zenoh_hub() -> Callable[[], ZenohConfig]:
    """Factory of Zenoh configs that all meet at one loopback endpoint.

    The first config returned listens on a fresh port; every later one connects to it. Multicast
    scouting is off in all of them.
    """
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    made: list[ZenohConfig] = []

    def make() -> ZenohConfig:
        if not made:
            cfg = ZenohConfig(mode="peer", listen=[endpoint], connect=[], multicast_scouting=False)
        else:
            cfg = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], multicast_scouting=False)
        made.append(cfg)
        return cfg

    return make


@pytest.fixture
def paper_library() -> Path:
    """The paper's motion library beside the repo; skips the test when it is absent."""
    if not PAPER_LIBRARY.is_dir():
        pytest.skip("../shared/data/paper-library not present")
    return PAPER_LIBRARY


@pytest.fixture
def reference_dir() -> Path:
    """../shared/reference; skips the test when it is absent."""
    if not REFERENCE.is_dir():
        pytest.skip("../shared/reference not present")
    return REFERENCE


def _signalled(args: Sequence[str], signals: Sequence[tuple[int, float]], ready: str = "ready",
               timeout: float = 60.0, ready_timeout: float = 180.0, **popen: Any) -> subprocess.CompletedProcess[str]:
    """Run ``python ARGS`` in the repo, wait for its first line, send each signal after its pause, collect its end.

    Args:
        args: The interpreter's arguments (``["-c", CODE, ...]`` or ``["-m", MODULE, ...]``).
        signals: ``(signal, pause_s)`` pairs, sent in order once the child printed its first line.
        ready: What that first line starts with (asserted: a child that died before it shows its stderr).
        timeout: Seconds the child has to end after the last signal.
        ready_timeout: Seconds it has to print its first line (imports on a loaded machine take a while).
        popen: More :class:`subprocess.Popen` arguments (``env``, ``preexec_fn``).

    Returns:
        The exit status, stdout after the first line, and stderr. The child is killed if it outlives ``timeout``.
    """
    proc = subprocess.Popen([sys.executable, *args], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, **popen)
    try:
        assert proc.stdout is not None
        if not select.select([proc.stdout], [], [], ready_timeout)[0]:  # a child that hangs before its first line
            proc.kill()
            raise AssertionError(f"the child printed nothing in {ready_timeout:g} s: "
                                 f"{proc.communicate(timeout=10)[1]}")
        first = proc.stdout.readline()
        if not first.startswith(ready):
            proc.kill()
            raise AssertionError(f"the child printed {first!r}, not {ready!r}...: {proc.communicate(timeout=10)[1]}")
        for sig, pause in signals:
            time.sleep(pause)
            proc.send_signal(sig)
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.fixture
def signalled() -> Callable[..., subprocess.CompletedProcess[str]]:
    """Start a Python child, signal it once it is ready, and read how it ended (see :func:`_signalled`)."""
    return _signalled


def _wait_until(pred: Callable[[], bool], timeout: float, interval: float = 0.05) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(interval)
    return False


@pytest.fixture
def wait_until() -> Callable[..., bool]:
    """``wait_until(pred, timeout, interval=0.05)``: poll ``pred`` until it holds (True) or ``timeout`` passes."""
    return _wait_until


COLLECTED = pytest.StashKey[int]()
"""How many tests this session collected (after -k/-m deselection); see :func:`whole_suite`."""


def pytest_collection_finish(session: pytest.Session) -> None:
    session.config.stash[COLLECTED] = len(session.items)


@pytest.fixture
def whole_suite_count(request: pytest.FixtureRequest) -> int | None:
    """The number of tests collected when this session runs the whole suite as ``make test`` does, else None."""
    return _whole_suite(request.config)


def _whole_suite(config: pytest.Config) -> int | None:
    opt = config.option
    if getattr(opt, "keyword", "") or getattr(opt, "markexpr", "") or getattr(opt, "deselect", None):
        return None
    if {str(Path(a).resolve()) for a in config.args} != {str(REPO / "tests")}:
        return None
    return config.stash.get(COLLECTED, None)
