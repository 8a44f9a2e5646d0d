"""Process plumbing shared by every service: logging, one-line errors, clean shutdown on signals."""

from __future__ import annotations

import faulthandler
import gc
import logging
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

from shared.arguments import ArgumentParser
from shared.config import ConfigError, ZenohConfig, add_config_arguments, resolve_config
from shared.native_threads import limit_blas_threads
from shared.signal_relay import interrupt_main_thread, relaying, watch_signals

__all__ = ["setup_logging", "fail", "stop_on_signals", "interruptible", "cli_errors", "UserError", "service_main",
           "help_text", "freeze_startup_heap", "watch_parent", "wait_for_stop", "lower_priority", "SHUTDOWN_GRACE_S",
           "SIGNAL_ECHO_S", "STOP_POLL_S", "FORCED_EXIT", "PARENT_ENV", "OWN_LOGGERS"]

SHUTDOWN_GRACE_S = 10.0
"""Seconds a process may take to stop after SIGINT/SIGTERM before it exits anyway (:func:`stop_on_signals`)."""
SIGNAL_ECHO_S = 0.1
"""A second signal this soon after the first is the same interrupt, delivered twice (coreutils ``timeout`` forwards
the SIGINT the terminal sent the whole process group), not a second one: :func:`stop_on_signals` ignores it."""
RELAY_AFTER_S = 0.05
"""How long :func:`interruptible` lets the main thread run its handler itself before passing the signal on to it."""
FORCED_EXIT = 3
"""Exit status of a process that did not stop within :data:`SHUTDOWN_GRACE_S` (or got a second signal)."""
OWN_LOGGERS = ("foresight", "shared", "services", "tools")
"""The loggers of Foresight's code (its ``foresight.*`` names and its modules'), which ``--log-level`` sets."""
PARENT_ENV = "FORESIGHT_PARENT_PID"
"""Environment variable with the pid of the process that started this one (``foresight demo``, tests)."""


class UserError(Exception):
    """An error caused by the user's input (file, option, data) rather than a bug."""


def help_text(doc: str) -> str:
    """A docstring as ``--help`` text.

    reST inline literals (double backticks) become single backticks, and a cross-reference (a ``:mod:`` or
    ``:func:`` role, say) the name it refers to, in single backticks.
    """
    return re.sub(r":(?:mod|func|class|meth|data|attr|exc):`~?([^`]+)`", r"`\1`", doc).replace("``", "`")


def setup_logging(level: str = "INFO") -> None:
    """Log to stderr with time, logger name and level (idempotent).

    Raises:
        ValueError: If ``level`` is not a level name (a section's ``log_level`` is checked against its choices;
            a typo must not fall back to INFO without a word).
    """
    if not isinstance(logging.getLevelName(level.upper()), int):
        raise ValueError(f"log level {level!r}: not one of DEBUG, INFO, WARNING, ERROR")
    root = logging.getLogger()
    if not root.handlers:
        asked = getattr(logging, level.upper())
        # DEBUG is Foresight's own: other libraries' (matplotlib's font search, filelock's every lock, ...) stay at
        # INFO, or a planner's per-plan lines came buried in hundreds of theirs
        logging.basicConfig(level=max(asked, logging.INFO),
                            format="%(asctime)s %(name)s %(levelname)s %(message)s", stream=sys.stderr)
        for name in OWN_LOGGERS:
            logging.getLogger(name).setLevel(asked)


def fail(prog: str, message: str, code: int = 2) -> int:
    """Print ``prog: error: message`` on one line to stderr and return ``code``."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return code


@contextmanager
def cli_errors(prog: str) -> Iterator[None]:
    """Turn user-facing errors into a one-line message and exit status 2 (no traceback)."""
    try:
        yield
    except (ConfigError, UserError, FileNotFoundError) as exc:
        raise SystemExit(fail(prog, str(exc))) from None
    except BrokenPipeError:  # output piped into `head`, which exited early: not an error (tools.foresight says 0)
        raise
    except OSError as exc:  # a path that is a directory, under a file, not writable; a full disk
        where = f"{exc.filename}: " if exc.filename else ""
        raise SystemExit(fail(prog, f"{where}{exc.strerror or exc}")) from None
    except ValueError as exc:
        # Validation errors of our own modules (SceneError, LibraryError, ProtocolError, ...) are ValueErrors
        if type(exc).__module__.startswith(("shared", "services")):
            raise SystemExit(fail(prog, str(exc))) from None
        raise


@contextmanager
def interruptible(stop: threading.Event) -> Iterator[None]:
    """Within the block, SIGINT/SIGTERM set ``stop`` and interrupt the main thread at once (``KeyboardInterrupt``).

    For work that checks no stop event and leaves nothing to close or finalise when cut short (training a
    prediction model, written whole or not at all, before any service has started): Ctrl-C then takes effect
    at once, not after a minute of training. A signal the kernel handed to another thread is passed on to the
    main thread (:mod:`shared.signal_relay`): it would otherwise wait for the main thread's sleep to end. Outside
    the main thread it changes nothing.
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

    def arrived(signum: int) -> None:  # the relay thread
        stop.set()
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
        with lock:  # no relayed signal reaches the handlers restored below
            open_[0] = False
        if unwatch is not None:
            unwatch()
        for s, h in old.items():
            signal.signal(s, h)


def stop_on_signals(stop: threading.Event, grace_s: float | None = None, prog: str | None = None
                    ) -> Callable[[], None]:
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
    (default: the script's name). All of this happens in the signal relay's thread (:mod:`shared.signal_relay`),
    not in the handler: the main thread may be the one stuck, and the kernel may give the signal to any thread.
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
            _forced_exit(prog, why, stacks)

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


def watch_parent(stop: threading.Event, period_s: float = 0.5) -> int | None:
    """Set ``stop`` when the process that started this one has gone (a thread; returns the parent's pid).

    Services started by ``foresight demo`` run in their own process group (a terminal's Ctrl-C reaches
    the demo only, which stops them in order); should the demo itself be killed, its services notice
    here (they are re-parented) and stop cleanly, the executor closing its MCAP. Only when
    :data:`PARENT_ENV` is set; a service started by hand has no parent to watch.

    Returns:
        The watched parent's pid, or None when there is none to watch.
    """
    try:
        parent = int(os.environ.get(PARENT_ENV, ""))
    except ValueError:
        return None
    if os.getppid() != parent:
        try:
            os.kill(parent, 0)
        except ProcessLookupError:  # it died while this process was starting (importing): stop now, never orphaned
            logging.getLogger("foresight").warning("the process that started this one (pid %d) has exited; "
                                                   "stopping", parent)
            stop.set()
            return parent
        except PermissionError:  # alive, another user's: not this process's parent
            pass
        return None  # alive but not the parent: a grandchild inherited the variable, nothing to watch

    def watch() -> None:
        while not stop.wait(period_s):
            if os.getppid() != parent:
                logging.getLogger("foresight").warning("the process that started this one (pid %d) has exited; "
                                                       "stopping", parent)
                stop.set()
                return

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()
    return parent


def freeze_startup_heap() -> int:
    """Move every object alive now out of the garbage collector's reach (``gc.freeze``); returns their count.

    A service imports torch, builds its models and compiles its kernels before it serves: about a
    million long-lived objects that every full (generation 2) collection would walk again. Measured
    in ``foresight demo --mode realtime`` (2026-11-25): such collections stopped the planner for up to
    0.2 s and the executor for 0.1 s in mid-run, the reaction-time outliers of ``foresight log latency``.
    Frozen, they are never scanned; what the service allocates while it serves is collected as usual.
    Called by :func:`service_main` only (a process's own entry point), never in-process.

    Returns:
        The number of objects frozen.
    """
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


def service_main(argv: list[str] | None, prog: str, *, section: str, config_cls: type, description: str,
                 make: Callable[[Any, ZenohConfig, threading.Event], Callable[[], Any]]) -> int:
    """The ``main`` of every service: options, logging, one-line errors, SIGINT/SIGTERM, run.

    Args:
        argv: Command-line arguments (None: ``sys.argv[1:]``).
        prog: Program name for help and errors.
        section: Config section, e.g. ``"planner"``.
        config_cls: The section's config dataclass (with a ``log_level`` field).
        description: ``--help`` text.
        make: ``(config, zenoh_config, stop) -> run``: builds the service (bad input raises a
            one-line error) and returns a callable that serves until ``stop`` is set; an ``int`` it returns is
            the exit status (the executor's 1: a lock-step run that went on without its inputs).

    ``make`` may not open anything that must be closed (a session, a log): a SIGINT/SIGTERM while it builds ends
    the process at once (:func:`interruptible`), status 0; while the service runs, the signal sets ``stop``.

    Returns:
        The exit status: 0 when the service stopped (or what ``run`` returned), 2 on bad input.
    """
    parser = ArgumentParser(prog=prog, description=description)
    add_config_arguments(parser, section, config_cls)
    args = parser.parse_args(argv)
    stop = threading.Event()
    with cli_errors(prog):
        limit_blas_threads()  # python -m services.X does not pass through tools.foresight
        cfg, zcfg = resolve_config(section, config_cls, args)
        if zcfg.security_dir:  # a refused certificate ends the service before its models load (3-4 s: the planner)
            from shared.security import ROLES
            from shared.security.certificates import verify_role

            if section in ROLES:  # the others (ros2, simrobot) refuse security themselves, naming why
                verify_role(zcfg.security_dir, zcfg.role)  # what opening the session checks first
        setup_logging(cfg.log_level)
        restore = stop_on_signals(stop, prog=prog)
        watch_parent(stop)
        try:
            try:
                # building checks no stop event (the planner compiles its kernels for up to a minute) and opens
                # nothing to close: a signal now ends it at once, not after the grace with a dump of every stack
                with interruptible(stop):
                    run = None if stop.is_set() else make(cfg, zcfg, stop)
            except KeyboardInterrupt:
                run = None
                _exit_within(SHUTDOWN_GRACE_S, prog)  # a worker the build started must not hold the exit unbounded
            if run is None:
                logging.getLogger("foresight").info("%s: stopped while starting", prog)
                return 0
            logging.getLogger("foresight").debug("%d start-up objects frozen out of the garbage collector",
                                                 freeze_startup_heap())
            status = run()
        finally:
            restore()
    return status if isinstance(status, int) and not isinstance(status, bool) else 0


def _exit_within(grace_s: float, prog: str) -> None:
    """Exit with :data:`FORCED_EXIT` unless the process has ended within ``grace_s`` (a daemon timer).

    After a signal cut a service's build short: a thread the build had started (a compile pool) would otherwise
    keep the interpreter from exiting for as long as it runs, with :func:`stop_on_signals`' watchdog, replaced by
    :func:`interruptible`'s handler, never started.
    """
    def force() -> None:
        time.sleep(grace_s)
        _forced_exit(prog, f"did not exit within {grace_s:g} s of stopping while starting")

    threading.Thread(target=force, name="start-watchdog", daemon=True).start()


def _unblock(signals: Iterable[int]) -> None:
    """Unblock ``signals`` in this (the main) thread: a handler of a blocked signal never runs.

    A blocked mask is inherited across fork and exec, and Python's ``signal.signal`` leaves it as it is: a process
    started by a parent (a test runner, a process manager) whose thread had SIGTERM blocked then ignored ``docker
    compose down``'s SIGTERM and Ctrl-C until it was killed.
    """
    signal.pthread_sigmask(signal.SIG_UNBLOCK, list(signals))


def _forced_exit(prog: str | None, why: str, stacks: bool = True) -> None:
    """Say why in one line (with every thread's stack: where it was stuck) and exit with :data:`FORCED_EXIT` now."""
    print(f"{prog or os.path.basename(sys.argv[0]) or 'foresight'}: {why}; exiting with status {FORCED_EXIT}"
          + (" (stacks of every thread follow)" if stacks else ""), file=sys.stderr, flush=True)
    if stacks:
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
    os._exit(FORCED_EXIT)


def lower_priority(nice: int) -> None:
    """Lower this process's CPU priority by ``nice`` (0: unchanged).

    A command that only watches or republishes (``foresight ros2``, ``foresight view``) must not take CPU from the
    planning loop on a shared machine. Call it from the command's own process only, never from a process it runs
    inside of.
    """
    if nice:
        os.nice(nice)
