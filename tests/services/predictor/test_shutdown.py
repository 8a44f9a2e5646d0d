"""A predictor obeys SIGTERM promptly after its router went away (issue 12, item 5c)."""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

from services.processes import ServiceProcess, free_port

REPO = Path(__file__).resolve().parents[3]


def test_predictor_stops_on_sigterm_after_its_router_was_killed(small_model, tmp_path):
    model = tmp_path / "model.npz"
    small_model.save(model)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = ServiceProcess("router", "tools", ["router", "--listen", endpoint], tmp_path / "router.log")
    predictor = ServiceProcess("predictor", "services.predictor",
                               ["--model", str(model), "--connect", endpoint, "--listen", "tcp/127.0.0.1:0"],
                               tmp_path / "predictor.log")
    try:
        router.start()
        predictor.start()
        deadline = time.monotonic() + 120
        while "predictor: model" not in predictor.tail(20) and time.monotonic() < deadline:
            assert predictor.running, predictor.tail(5)
            time.sleep(0.1)
        time.sleep(1.0)  # connected to the router
        router.proc.kill()
        router.proc.wait(timeout=10)
        time.sleep(2.0)  # the router has gone
        predictor.proc.send_signal(signal.SIGTERM)
        code = predictor.proc.wait(timeout=60)  # bounded: the shutdown watchdog forces an exit after 10 s
    finally:
        predictor.stop(timeout=5)
        router.stop(timeout=5)
    assert code == 0, predictor.tail(10)  # stopped by itself, not forced (status 3)
    assert "predictor: stopped after" in predictor.tail(5)


BLOCKED = """
import sys, threading, time
from shared import runtime
stop = threading.Event()
runtime.stop_on_signals(stop, grace_s=1.0, prog="blocked")
if sys.argv[1:] == ["stopping"]:
    stop.set()  # stopping on its own already (--stop-with, its parent gone) when the signal comes
print("ready", flush=True)
while True:  # a call that does not look at the stop event, in short slices: Python runs a signal's handler only
    time.sleep(0.05)  # between bytecodes, and one landing just before a long sleep's syscall waited for it to end
"""


def _signalled(signalled: Callable[..., subprocess.CompletedProcess[str]], *signals: tuple[signal.Signals, float],
               args: tuple[str, ...] = (), masked: bool = False) -> tuple[int, str]:
    """A blocked process sent each signal after its pause (s); its exit status and stderr."""
    mask = (lambda: signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGINT, signal.SIGTERM])) if masked else None
    end = signalled(["-c", BLOCKED, *args], signals, preexec_fn=mask)
    return end.returncode, end.stderr


def test_a_process_stuck_in_a_call_exits_after_the_grace_and_says_where(signalled):
    code, err = _signalled(signalled, (signal.SIGTERM, 0.0))
    assert code == 3, err
    assert "blocked: did not stop within 1 s of SIGTERM; exiting with status 3" in err  # named by its prog
    assert 'File "<string>", line 10' in err  # the stack says where it was stuck


def test_a_process_started_with_the_signals_blocked_still_obeys_them(signalled):
    """A blocked mask is inherited across exec and signal.signal leaves it: such a process (started by a thread that
    had them blocked) never ran its handler and hung until killed."""
    code, err = _signalled(signalled, (signal.SIGTERM, 0.0), masked=True)
    assert code == 3 and "did not stop within 1 s of SIGTERM" in err, err


def test_a_second_signal_exits_at_once(signalled):
    code, err = _signalled(signalled, (signal.SIGINT, 0.0), (signal.SIGTERM, 0.2))
    assert code == 3 and "second SIGTERM while stopping" in err, err
    assert "stacks" not in err and "File " not in err  # one line: whoever sent it wants out, not a dump


def test_one_interrupt_delivered_twice_at_once_is_one_interrupt(signalled):
    """``timeout`` forwards the SIGINT a terminal sent the process group: two within milliseconds dumped every
    thread's stack and exited with status 3 at once."""
    code, err = _signalled(signalled, (signal.SIGINT, 0.0), (signal.SIGINT, 0.0))
    # the process never stops by itself: the grace, not the echo, ends it
    assert code == 3 and "second" not in err and "did not stop within 1 s of SIGINT" in err, err


def test_the_first_signal_to_a_process_already_stopping_on_its_own_gets_the_grace(signalled):
    """With stop already set (--stop-with, a parent gone) the first and only SIGTERM (docker compose down, the
    demo's stop) was taken for a second one: exit 3 at once, 'second SIGTERM', its shutdown cut off."""
    code, err = _signalled(signalled, (signal.SIGTERM, 0.0), args=("stopping",))
    assert code == 3 and "second" not in err and "did not stop within 1 s of SIGTERM" in err, err
