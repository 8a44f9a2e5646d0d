"""Progress bars of long work (training, leave-one-out, benchmarks): tqdm, in whole lines when not on a terminal.

On a terminal tqdm redraws its bar in place with carriage returns. Written to a file or a pipe (``make demo >
demo.log``, a CI log) the same bar became one line of every frame joined by carriage returns (a review of the first
``make demo``: ``GMM per class`` and ``demos volumes``, each one long line). Off a terminal :func:`progress` writes
each update as a line of its own, at most one every :data:`LOG_INTERVAL_S` seconds (and the last), so a log
reads as progress and stays short.
"""

from __future__ import annotations

import sys
import traceback
from collections.abc import Iterable, Iterator
from typing import IO, Any, TypeVar

from tqdm import tqdm

__all__ = ["LOG_INTERVAL_S", "close_interrupted", "progress"]

T = TypeVar("T")

LOG_INTERVAL_S = 5.0
"""Seconds between two progress lines written off a terminal."""


class _Lines:
    """A text stream taking tqdm's in-place frames (a carriage return and the bar) as one line each."""

    def __init__(self, out: IO[str]) -> None:
        self.out = out

    def write(self, s: str) -> int:
        line = s.replace("\r", "").rstrip()
        if line:
            self.out.write(line + "\n")
        return len(s)

    def flush(self) -> None:
        self.out.flush()


def progress(items: Iterable[T], desc: str, unit: str, total: int | None = None, enabled: bool = True,
             file: IO[str] | None = None) -> Iterator[T]:
    """``items`` with a progress bar on ``file`` (default stderr) when ``enabled``.

    Args:
        items: What is worked through.
        desc: The bar's label.
        unit: What one item is (``class``, ``demo``).
        total: Number of items, where ``items`` has no length (a generator).
        enabled: False: no bar (a caller's ``progress=False``).
        file: Where the bar goes; a terminal gets tqdm's bar, anything else whole lines.
    """
    out = sys.stderr if file is None else file
    tty = bool(getattr(out, "isatty", lambda: False)())
    kw: dict[str, Any] = {"file": out} if tty else {"file": _Lines(out), "mininterval": LOG_INTERVAL_S, "ncols": 80}
    return iter(tqdm(items, desc=desc, unit=unit, total=total, disable=not enabled, **kw))


def close_interrupted(exc: BaseException) -> None:
    """Finish what the work ``exc`` cut short left open (its progress bars' lines), before the line that says so.

    A progress bar is closed when the loop it counts is left, and the loop Ctrl-C broke out of is left only when the
    traceback's frames go, after the "interrupted" line: a half bar was the last thing on the terminal (a new
    user's ``foresight train``). Clearing the frames closes it now, with the count it had reached.
    """
    traceback.clear_frames(exc.__traceback__)
