"""Process plumbing shared by every service: logging, one-line errors, its main (stopping: :mod:`shared.stopping`)."""

from __future__ import annotations

import gc
import logging
import os
import re
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from shared.arguments import ArgumentParser
from shared.config import ConfigError, ZenohConfig, add_config_arguments, resolve_config
from shared.native_threads import limit_blas_threads
from shared.stopping import (
    FORCED_EXIT,
    PARENT_ENV,
    SHUTDOWN_GRACE_S,
    SIGNAL_ECHO_S,
    STOP_POLL_S,
    StoppedWhileStarting,
    exit_within,
    interruptible,
    stop_on_signals,
    wait_for_stop,
)

__all__ = ["setup_logging", "fail", "stop_on_signals", "interruptible", "cli_errors", "UserError", "service_main",
           "help_text", "freeze_startup_heap", "watch_parent", "wait_for_stop", "lower_priority", "SHUTDOWN_GRACE_S",
           "SIGNAL_ECHO_S", "STOP_POLL_S", "FORCED_EXIT", "PARENT_ENV", "OWN_LOGGERS"]

OWN_LOGGERS = ("foresight", "shared", "services", "tools")
"""The loggers of Foresight's code (its ``foresight.*`` names and its modules'), which ``--log-level`` sets."""


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
                with interruptible(stop, SHUTDOWN_GRACE_S, prog):
                    run = None if stop.is_set() else make(cfg, zcfg, stop)
            except KeyboardInterrupt:
                run = None
                exit_within(SHUTDOWN_GRACE_S, prog, "of stopping while starting")  # nor a worker the build started
            if run is None:
                logging.getLogger("foresight").info("%s: stopped while starting", prog)
                return 0
            logging.getLogger("foresight").debug("%d start-up objects frozen out of the garbage collector",
                                                 freeze_startup_heap())
            try:
                status = run()
            except StoppedWhileStarting as exc:  # docker compose down while the router restarted: no bad input
                logging.getLogger("foresight").info("%s: %s", prog, exc)
                status = 0
            if stop.is_set():  # a thread the service left behind must not hold the exit unbounded
                exit_within(SHUTDOWN_GRACE_S, prog, "of its stop")
        finally:
            restore()
    return status if isinstance(status, int) and not isinstance(status, bool) else 0


def lower_priority(nice: int) -> None:
    """Lower this process's CPU priority by ``nice`` (0: unchanged).

    A command that only watches or republishes (``foresight ros2``, ``foresight view``) must not take CPU from the
    planning loop on a shared machine. Call it from the command's own process only, never from a process it runs
    inside of.
    """
    if nice:
        os.nice(nice)
