"""What reading a library left out, said once: one line per file with dropped demonstrations.

:func:`shared.library.load_library` logs these lines (logger ``foresight.library``, WARNING) on every
path that reads a library: the replayer, the demo, training and the experiments. ``foresight library
info`` and ``validate`` print the issues themselves, one per demonstration. A command that reads one library
many times (``foresight eval all``: every part reads it, in worker processes) says each line once with
:func:`said_once`.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from .motions import MotionLibrary

__all__ = ["MAX_LISTED", "drop_lines", "report_drops", "said_once", "say_once"]

log = logging.getLogger("foresight.library")

MAX_LISTED = 4
"""Dropped demonstrations named on a file's line; more are counted (``... and 3 more``)."""


def _file_of(lib: MotionLibrary, class_name: str) -> str:
    """The file a class came from: ``<dir>/<class>.csv`` for a CSV directory, the ``.npz`` itself otherwise."""
    src = Path(lib.source)
    if src.is_dir():
        return str(src / f"{class_name}.csv")
    return f"{lib.source} (class {class_name})"


def drop_lines(lib: MotionLibrary) -> list[str]:
    """One line per file that lost demonstrations (empty when nothing was dropped).

    Example: ``library runs/lib/compound_1.csv: dropped 1 demonstration (24 kept): block 1 (lines
    101-200: line 123: nan in column 8 (torso_z))``.
    """
    kept = Counter(d.class_name for d in lib.demos)
    lines: list[str] = []
    order = list(dict.fromkeys([*lib.class_names, *(i.class_name for i in lib.issues)]))
    for name in order:
        issues = [i for i in lib.issues if i.class_name == name]
        if not issues:
            continue
        blocks = [i for i in issues if i.block >= 0]
        whole = [i.reason for i in issues if i.block < 0]
        parts: list[str] = []
        if blocks:
            n = len(blocks)
            listed = "; ".join(f"block {i.block} ({i.reason})" for i in blocks[:MAX_LISTED])
            more = f"; ... and {n - MAX_LISTED} more" if n > MAX_LISTED else ""
            parts.append(f"dropped {n} demonstration{'s' if n != 1 else ''} ({kept[name]} kept): {listed}{more}")
        parts.extend(whole)
        lines.append(f"library {_file_of(lib, name)}: " + "; ".join(parts))
    return lines


def report_drops(lib: MotionLibrary, logger: logging.Logger | None = None) -> list[str]:
    """Log :func:`drop_lines` at WARNING (one record per file); returns the lines."""
    lines = drop_lines(lib)
    for line in lines:
        (logger or log).warning("%s", line)
    return lines


class _Once(logging.Filter):
    """Lets a drop line through the first time only; ``said`` holds the lines said already (elsewhere too)."""

    def __init__(self, said: Iterable[str] = ()) -> None:
        super().__init__()
        self.said = set(said)

    def filter(self, record: logging.LogRecord) -> bool:
        line = record.getMessage()
        if line in self.said:
            return False
        self.said.add(line)
        return True


def say_once(said: Iterable[str] = ()) -> None:
    """From now on in this process, log each drop line once, and none of ``said`` (lines another process logged).

    For worker processes (a ``multiprocessing`` initializer): their parent read the library first and said
    what it dropped.
    """
    log.addFilter(_Once(said))


@contextmanager
def said_once(said: Iterable[str] = ()) -> Iterator[None]:
    """Within the block, :func:`say_once`; the filter is removed on leaving it."""
    once = _Once(said)
    log.addFilter(once)
    try:
        yield
    finally:
        log.removeFilter(once)
