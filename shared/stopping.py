"""Stopping a process on SIGINT/SIGTERM: at once while it builds, within a grace while it runs, never unbounded.

:func:`stop_on_signals` sets a stop event and starts a watchdog; :func:`interruptible` cuts work that checks no
stop event short at once; :func:`exit_within` bounds the exit after a stop. What a process must do to stop (close
its session, finalise its MCAP) is its own; these only bound how long it may take. The signal relay
(:mod:`shared.signal_relay`) acts for the main thread when a native call holds it.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager

from shared.signal_relay import interrupt_main_thread, relaying, watch_signals

__all__ = ["StoppedWhileStarting", "stop_on_signals", "interruptible", "wait_for_stop", "exit_within",
           "SHUTDOWN_GRACE_S", "SIGNAL_ECHO_S", "STOP_POLL_S", "FORCED_EXIT", "PARENT_ENV"]

class StoppedWhileStarting(Exception):  # noqa: N818 (a stop, not an error)
    """A stop (a signal) came while the service was still starting, e.g. waiting for its router: it ends with 0."""


SHUTDOWN_GRACE_S = 10.0
"""Seconds a process may take to stop after SIGINT/SIGTERM before it exits anyway (:func:`stop_on_signals`)."""
SIGNAL_ECHO_S = 0.1
"""A second signal this soon after the first is the same interrupt, delivered twice (coreutils ``timeout`` forwards
the SIGINT the terminal sent the whole process group), not a second one: :func:`stop_on_signals` ignores it."""
RELAY_AFTER_S = 0.05
"""How long :func:`interruptible` lets the main thread run its handler itself before passing the signal on to it."""
FORCED_EXIT = 3
"""Exit status of a process that did not stop within :data:`SHUTDOWN_GRACE_S` (or got a second signal)."""
PARENT_ENV = "FORESIGHT_PARENT_PID"
"""Environment variable with the pid of the process that started this one (``foresight demo``, tests)."""


@contextmanager
def interruptible(stop: threading.Event, grace_s: float | None = None, prog: str | None = None) -> Iterator[None]:
    """Within the block, SIGINT/SIGTERM set ``stop`` and interrupt the main thread at once (``KeyboardInterrupt``).

    For work that checks no stop event and leaves nothing to close or finalise when cut short (training a
    prediction model, written whole or not at all, before any service has started): Ctrl-C then takes effect
    at once, not after a minute of training. A signal the kernel handed to another thread is passed on to the
    main thread (:mod:`shared.signal_relay`): it would otherwise wait for the main thread's sleep to end. Outside
    the main thread it changes nothing. With ``grace_s``, as :func:`stop_on_signals` (whose watchdog this block
    replaces): a native call that never returns to Python is ended ``grace_s`` after the first signal, with the
    stacks, and a second signal exits at once (``prog`` names the process); without, a service's build ignored a
    second SIGTERM and exited 13 s after the first (a review).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    handled = threading.Event()
    lock = threading.Lock()
    open_ = [True]
    relayed: list[int] = []

    def handler(signum: int, frame: object) -> None:
        stop.set()
        if not handled.is_set():  # once: a relayed copy of the same signal must not interrupt the clean-up
            handled.set()
            raise KeyboardInterrupt

    first_at: list[float] = []
    closed = threading.Event()

    def watchdog(name: str) -> None:
        if not closed.wait(grace_s):
            _forced_exit(prog, f"did not stop within {grace_s:g} s of {name} while starting")

    def arrived(signum: int) -> None:  # the relay thread
        stop.set()
        if grace_s is not None:
            name = signal.Signals(signum).name
            with lock:
                if first_at and time.monotonic() - first_at[0] >= SIGNAL_ECHO_S and open_[0]:
                    _forced_exit(prog, f"second {name} while starting", stacks=False)
                if not first_at:
                    first_at.append(time.monotonic())
                    threading.Thread(target=watchdog, args=(name,), name="start-watchdog", daemon=True).start()
        if handled.wait(RELAY_AFTER_S):
            return  # the main thread got it, or was running bytecode and ran its handler
        with lock:
            if open_[0] and not handled.is_set() and not relayed:
                relayed.append(signum)  # once: a native call that retries on EINTR would get one every 50 ms
                interrupt_main_thread(signum)

    for s in old:
        signal.signal(s, handler)
    _unblock(old)
    unwatch = watch_signals(arrived)
    try:
        yield
    finally:
        closed.set()
        with lock:  # no relayed signal reaches the handlers restored below
            open_[0] = False
        if unwatch is not None:
            unwatch()
        for s, h in old.items():
            signal.signal(s, h)


def stop_on_signals(stop: threading.Event, grace_s: float | None = None, prog: str | None = None,
                    context: Callable[[], str | None] | None = None) -> Callable[[], None]:
    """Set ``stop`` on SIGINT/SIGTERM (main thread only); returns a function restoring the old handlers.

    A process must obey the signal even when a call it is in blocks (a Zenoh call whose router went
    away, a library that ignores the stop event): ``grace_s`` (default :data:`SHUTDOWN_GRACE_S`) after
    the first signal, unless the restore function has been called by then, it prints one line and the
    stacks of every thread (where it was stuck) to stderr and exits with :data:`FORCED_EXIT`; a second
    signal exits so at once, with one line (the person who sent it wants out, not a dump). A signal within
    :data:`SIGNAL_ECHO_S` of the first is the first one delivered again and ignored. What the stop had
    finished by then (the executor's MCAP, closed before its session) is kept. The first signal is the first
    one received, whether or not ``stop`` was already set (by ``--stop-with``, a parent gone, the service itself):
    a process that is stopping on its own still gets its grace. ``prog`` names the process in those lines
    (default: the script's name); ``context``, called then, may add what the person needs to know to that one line
    (``foresight demo``: where the run's files are and that its services stop on their own). All of this happens
    in the signal relay's thread (:mod:`shared.signal_relay`), not in the handler: the main thread may be the one
    stuck, and the kernel may give the signal to any thread.
    Where there is no relay (another owner of the wakeup descriptor, now or since; a forked child), the handler
    acts, when it gets to run.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    restored = threading.Event()
    grace = SHUTDOWN_GRACE_S if grace_s is None else grace_s

    first_at: list[float] = []
    lock = threading.Lock()

    def force(why: str, stacks: bool = True) -> None:
        if not restored.is_set():
            _forced_exit(prog, why, stacks, context)

    def watchdog(signame: str) -> None:
        if not restored.wait(grace):
            force(f"did not stop within {grace:g} s of {signame}")

    def on_signal(signum: int) -> None:  # in the relay thread (or in the handler where there is none)
        name = signal.Signals(signum).name
        with lock:
            if first_at:
                if time.monotonic() - first_at[0] < SIGNAL_ECHO_S:
                    return  # the first interrupt, delivered again
                force(f"second {name} while stopping", stacks=False)
            first_at.append(time.monotonic())
        stop.set()
        threading.Thread(target=watchdog, args=(name,), name="shutdown-watchdog", daemon=True).start()

    def handler(signum: int, frame: object) -> None:
        if unwatch is None or not relaying():  # no relay (or none any more): the main thread acts, when it can
            on_signal(signum)

    unwatch: Callable[[], None] | None = None
    for s in old:
        signal.signal(s, handler)
    _drop_parents_interrupt()
    _unblock(old)  # before the relay thread starts (the first call in a process): it inherits the mask
    unwatch = watch_signals(on_signal)

    def restore() -> None:
        restored.set()
        if unwatch is not None:
            unwatch()
        for s, h in old.items():
            signal.signal(s, h)

    return restore


STOP_POLL_S = 0.5
"""How often :func:`wait_for_stop` wakes to let a pending signal's handler run."""


def wait_for_stop(stop: threading.Event, poll_s: float = STOP_POLL_S) -> None:
    """Block until ``stop`` is set, waking every ``poll_s`` so that a signal's handler always gets to run.

    Python runs a handler in the main thread, between bytecodes. ``stop.wait()`` without a timeout is one long
    lock wait: a signal that lands after the wait has checked the flag and before it sleeps, or one the kernel
    hands to another thread (a native library's), only marks the handler as pending, and the handler (which
    sets ``stop``) would run when the wait ends, that is never. Waking every ``poll_s`` bounds that to ``poll_s``
    where :func:`stop_on_signals` has no relay thread to set ``stop`` at once (:mod:`shared.signal_relay`).
    """
    while not stop.wait(poll_s):
        pass


def exit_within(grace_s: float, prog: str, after: str) -> None:
    """Exit with :data:`FORCED_EXIT` unless the process has ended within ``grace_s`` (a daemon timer).

    After a signal cut a service's build short, or its run returned on a stop: a thread it had started (a compile
    pool, a worker) would otherwise keep the interpreter from exiting for as long as it runs (25 s in a review),
    the signal's watchdog being over. ``after`` completes "did not exit within N s ...".
    """
    def force() -> None:
        time.sleep(grace_s)
        _forced_exit(prog, f"did not exit within {grace_s:g} s {after}")

    threading.Thread(target=force, name="start-watchdog", daemon=True).start()


def _unblock(signals: Iterable[int]) -> None:
    """Unblock ``signals`` in this (the main) thread: a handler of a blocked signal never runs.

    A blocked mask is inherited across fork and exec, and Python's ``signal.signal`` leaves it as it is: a process
    started by a parent (a test runner, a process manager) whose thread had SIGTERM blocked then ignored ``docker
    compose down``'s SIGTERM and Ctrl-C until it was killed.
    """
    signal.pthread_sigmask(signal.SIG_UNBLOCK, list(signals))


def _drop_parents_interrupt() -> None:
    """Drop the SIGINT held since start by a process that a Foresight parent started (:data:`PARENT_ENV`).

    :class:`services.processes.ServiceProcess` forks its process with SIGINT blocked: until the fork has moved it
    into a process group of its own, a terminal's Ctrl-C to the parent's group reaches it too, and killed it before
    it had a handler ("replayer exited with status -2" after Ctrl-C of ``foresight demo``). That Ctrl-C is the
    parent's, which stops its services itself, in its own order: obeyed here, the service would stop on its own, and
    the parent's SIGTERM coming later would be a second signal (a forced exit).
    """
    if not os.environ.get(PARENT_ENV) or signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, []):
        return
    if signal.SIGINT in signal.sigpending():
        signal.sigtimedwait([signal.SIGINT], 0)


def _forced_exit(prog: str | None, why: str, stacks: bool = True, context: Callable[[], str | None] | None = None
                 ) -> None:
    """Say why in one line (with every thread's stack: where it was stuck) and exit with :data:`FORCED_EXIT` now.

    ``context()`` (when given and not empty) ends the line; a failure of it costs only its words, never the exit.
    """
    try:
        more = context() if context is not None else None
    except Exception:  # noqa: BLE001 (the exit must happen whatever the context does)
        more = None
    print(f"{prog or os.path.basename(sys.argv[0]) or 'foresight'}: {why}; exiting with status {FORCED_EXIT}"
          + (f"; {more}" if more else "") + (" (stacks of every thread follow)" if stacks else ""),
          file=sys.stderr, flush=True)
    if stacks:
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
    os._exit(FORCED_EXIT)
