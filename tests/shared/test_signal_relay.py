"""shared.signal_relay: a signal is seen at once, whichever thread the kernel delivered it to."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

from shared.signal_relay import watch_signals

REPO = Path(__file__).resolve().parents[2]

STACKED = """
import queue, signal, threading, time
from shared.signal_relay import watch_signals

for s in (signal.SIGINT, signal.SIGTERM):
    signal.signal(s, lambda signum, frame: None)  # the C handler writes the wakeup byte only beside a Python one
seen = queue.Queue()
outer = watch_signals(lambda signum: seen.put(("outer", signum, threading.current_thread().name)))
inner = watch_signals(lambda signum: seen.put(("inner", signum, threading.current_thread().name)))
other = threading.Thread(target=time.sleep, args=(60,), daemon=True)
other.start()

def on_other(sig):
    signal.pthread_kill(other.ident, sig)  # delivered to that thread, as the kernel may choose
    return seen.get(timeout=10)

print(on_other(signal.SIGINT))
inner()
print(on_other(signal.SIGTERM))
outer()
signal.pthread_kill(other.ident, signal.SIGTERM)
try:
    print(seen.get(timeout=1.0))
except queue.Empty:
    print("none")
"""


def _run(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


def test_only_the_innermost_callback_is_called_in_the_relay_thread_until_it_is_removed() -> None:
    assert _run(STACKED) == ["('inner', 2, 'signal-relay')", "('outer', 15, 'signal-relay')", "none"]


OWNED = """
import signal, socket
from shared.signal_relay import watch_signals

signal.signal(signal.SIGTERM, lambda signum, frame: None)
theirs, _ = socket.socketpair()
theirs.setblocking(False)
signal.set_wakeup_fd(theirs.fileno())  # an asyncio loop's, say
print(watch_signals(lambda signum: None), signal.set_wakeup_fd(-1) == theirs.fileno())
"""


def test_a_wakeup_descriptor_of_another_owner_is_left_to_it() -> None:
    """The caller then acts in its handler, as it did before the relay."""
    assert _run(OWNED) == ["None True"]


def test_outside_the_main_thread_nothing_is_relayed() -> None:
    got: list[object] = []
    thread = threading.Thread(target=lambda: got.append(watch_signals(lambda signum: None)))
    thread.start()
    thread.join(timeout=10)
    assert got == [None]


FORKED = """
import os, signal, threading, time
from shared import runtime

stop = threading.Event()
runtime.stop_on_signals(stop, grace_s=30.0, prog="parent")
pid = os.fork()
if pid == 0:
    os._exit(7 if stop.wait(5.0) else 8)  # the child's own stop, set by its own handler
time.sleep(1.0)
os.kill(pid, signal.SIGTERM)
_, status = os.waitpid(pid, 0)
print(os.waitstatus_to_exitcode(status), stop.is_set())
"""


def test_a_forked_child_obeys_its_own_signals_and_leaves_the_parent_alone() -> None:
    """A review: the child inherited the descriptor (the parent's socket) and a handler that left the acting to the
    relay; its SIGTERM set the parent's stop (the parent then exited 3 after its grace) and not its own."""
    assert _run(FORKED) == ["7 False"]


TAKEN = """
import asyncio, os, signal, threading
from shared import runtime

stop = threading.Event()
runtime.stop_on_signals(stop, grace_s=30.0, prog="taken")
loop = asyncio.new_event_loop()  # takes the wakeup descriptor for its own handler, and gives it back as -1
loop.add_signal_handler(signal.SIGUSR1, lambda: None)
loop.remove_signal_handler(signal.SIGUSR1)
loop.close()
os.kill(os.getpid(), signal.SIGTERM)
print(stop.wait(5.0))
"""


def test_a_descriptor_taken_after_the_relay_claimed_it_leaves_the_acting_to_the_handler() -> None:
    """A review: an asyncio loop that took the descriptor (and reset it) left SIGTERM with no one to act on it."""
    assert _run(TAKEN) == ["True"]
