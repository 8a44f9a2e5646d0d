"""Process plumbing shared by every service: logging, one-line errors, clean shutdown on signals."""

from __future__ import annotations

import logging
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from shared.config import ConfigError

__all__ = ["setup_logging", "fail", "stop_on_signals", "cli_errors", "UserError"]


class UserError(Exception):
    """An error caused by the user's input (file, option, data) rather than a bug."""


def setup_logging(level: str = "INFO") -> None:
    """Log to stderr with time, logger name and level (idempotent)."""
    root = logging.getLogger()
    if not root.handlers:
        logging.basicConfig(level=getattr(logging, level.upper(), logging.INFO),
                            format="%(asctime)s %(name)s %(levelname)s %(message)s", stream=sys.stderr)


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
    except ValueError as exc:
        # Validation errors of our own modules (SceneError, LibraryError, ProtocolError, ...) are ValueErrors
        if type(exc).__module__.startswith(("shared", "services")):
            raise SystemExit(fail(prog, str(exc))) from None
        raise


def stop_on_signals(stop: threading.Event) -> Callable[[], None]:
    """Set ``stop`` on SIGINT/SIGTERM (main thread only); returns a function restoring the old handlers."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum: int, frame: object) -> None:
        stop.set()

    for s in old:
        signal.signal(s, handler)

    def restore() -> None:
        for s, h in old.items():
            signal.signal(s, h)

    return restore
