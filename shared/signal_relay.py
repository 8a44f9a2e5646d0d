"""SIGINT and SIGTERM seen at once, whichever thread the kernel delivered them to.

The kernel hands a signal sent to a process (Ctrl-C, ``kill``, ``docker compose down``) to any one of its threads
that does not block it, not always the main thread. Python runs a signal's handler only in the main thread,
between bytecodes. So when the signal landed on another thread (OpenBLAS's, a Zenoh runtime's, torch's) while
the main thread slept or waited in a native call (the planner compiling its kernels), the handler ran when that
call ended: a build that checked no stop event ran on, and a stuck call was never cut short by the shutdown
watchdog, which the handler starts. A CI run saw it: a service signalled while it was built did not end in 30 s.

Python's own C-level handler runs in whichever thread got the signal, and writes the signal's number to the
wakeup file descriptor (:func:`signal.set_wakeup_fd`). :func:`watch_signals` points that descriptor at a socket
read by a thread of its own, which calls back as soon as the signal arrives. The callbacks form a stack, like
the handlers they stand beside: only the innermost (the last one registered and not yet removed) is called.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable

__all__ = ["WATCHED", "watch_signals", "relaying", "interrupt_main_thread"]

WATCHED = (signal.SIGINT, signal.SIGTERM)
"""The signals relayed (those a person or a process manager stops a Foresight process with)."""
ECHO_S = 1.0
"""How long the wakeup byte of a signal :func:`interrupt_main_thread` sent is waited for, to be dropped."""

log = logging.getLogger("foresight.signals")


class _Relay:
    """The process's wakeup socket and the thread reading it.

    One per process: the wakeup descriptor is one. A forked child forgets its parent's and makes its own.
    """

    def __init__(self) -> None:
        self.pid = os.getpid()
        self._read, self._write = socket.socketpair()
        self._write.setblocking(False)  # the C handler must never block; a full buffer drops the byte
        self._stack: list[Callable[[int], None]] = []
        self._echoes: list[tuple[int, float]] = []  # (signum, until): a copy sent to the main thread, not a signal
        self._lock = threading.Lock()
        threading.Thread(target=self._serve, name="signal-relay", daemon=True).start()

    def claim(self) -> bool:
        """Point the wakeup descriptor at this relay; False (and left as it was) when another owner has it."""
        old = signal.set_wakeup_fd(self._write.fileno(), warn_on_full_buffer=False)
        if old not in (-1, self._write.fileno()):  # an event loop's: not ours to take
            signal.set_wakeup_fd(old)
            return False
        return True

    def owns(self) -> bool:
        """Whether the wakeup descriptor is still this relay's (main thread only; an asyncio loop may have taken it)."""
        fd = self._write.fileno()
        old = signal.set_wakeup_fd(fd, warn_on_full_buffer=False)
        if old != fd:
            signal.set_wakeup_fd(old)
        return old == fd

    def expect_echo(self, signum: int) -> None:
        """The next wakeup byte of ``signum`` within :data:`ECHO_S` is a copy sent on: not dispatched."""
        with self._lock:
            self._echoes.append((signum, time.monotonic() + ECHO_S))

    def push(self, callback: Callable[[int], None]) -> Callable[[], None]:
        with self._lock:
            self._stack.append(callback)

        def remove() -> None:
            with self._lock:
                if callback in self._stack:
                    self._stack.remove(callback)
        return remove

    def _serve(self) -> None:
        while True:
            try:
                data = self._read.recv(256)
            except OSError:  # pragma: no cover - the socket is never closed while the process lives
                return
            for signum in data:
                if signum not in WATCHED:
                    continue
                with self._lock:
                    now = time.monotonic()
                    self._echoes = [e for e in self._echoes if e[1] > now]
                    echo = next((e for e in self._echoes if e[0] == signum), None)
                    if echo is not None:  # the copy interrupt_main_thread sent: that signal was dispatched already
                        self._echoes.remove(echo)
                    callback = self._stack[-1] if self._stack and echo is None else None
                if callback is None:
                    continue
                try:
                    callback(signum)
                except Exception:  # a bug in a callback must not end the relay for every later signal
                    log.exception("handling %s", signal.Signals(signum).name)


_relay: _Relay | None = None
_relay_lock = threading.Lock()


def _forget_in_child() -> None:
    """A forked child: the parent's relay thread is not in it, and the descriptor's socket is the parent's."""
    global _relay
    if _relay is not None:
        _relay = None
        try:
            signal.set_wakeup_fd(-1)  # else the child's signals woke the parent's relay, and stopped the parent
        except ValueError:  # pragma: no cover - forked from a thread other than the main one
            pass


os.register_at_fork(after_in_child=_forget_in_child)


def watch_signals(callback: Callable[[int], None]) -> Callable[[], None] | None:
    """Call ``callback(signum)`` in a relay thread as soon as the process gets SIGINT or SIGTERM, in any thread.

    Call it from the main thread, with a Python handler installed for both signals (without one, the C handler
    neither runs nor writes the wakeup byte). The handler still runs in the main thread when it can: the caller
    decides which of the two acts (:func:`shared.runtime.stop_on_signals` acts in the relay only).

    Args:
        callback: Called with the signal's number, in the relay thread, for each signal received while it is the
            innermost callback. It must be quick (the next signal waits for it) and thread-safe.

    Returns:
        A function removing ``callback``, or None where signals cannot be relayed (not the main thread, or the
        wakeup descriptor belongs to something else, such as an asyncio loop): the caller then acts in its
        handler, as before. The handler should also act when :func:`relaying` turns False (the descriptor taken
        since, a forked child).
    """
    global _relay
    if threading.current_thread() is not threading.main_thread():
        return None
    with _relay_lock:
        if _relay is None:
            _relay = _Relay()
        if not _relay.claim():
            return None
        return _relay.push(callback)


def relaying() -> bool:
    """Whether this process's signals reach the relay: its descriptor not taken since (call from the main thread)."""
    relay = _relay
    return relay is not None and relay.pid == os.getpid() and relay.owns()


def interrupt_main_thread(signum: int) -> None:
    """Deliver ``signum`` to the main thread itself, cutting short a sleep or a wait there (EINTR).

    Its handler then runs at once, in the main thread. A native call that retries on EINTR is not cut short: its
    handler runs when the call returns. The copy's own wakeup byte is not dispatched again (an outer callback, once
    the inner one is removed, took it for a new signal).
    """
    main = threading.main_thread().ident
    relay = _relay
    if main is None:
        return
    if relay is not None:
        relay.expect_echo(signum)
    signal.pthread_kill(main, signum)
