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
