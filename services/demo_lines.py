"""What a demo run prints as it goes: its table's rows (on a thread of their own) and its log's state at the end."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from pathlib import Path

from shared.runtime import UserError

__all__ = ["Lines", "log_phrase", "unexecuted"]


def log_phrase(mcap: Path, plan_topic: str | None = None, received: int = 0, summarised: int | None = None) -> str:
    """One phrase on the run's MCAP: complete (the executor finished it) or not, with its message count.

    With ``plan_topic``: its plans too, and how many of the ``received`` ones (the rows printed) came after the
    executor closed it, or how many it logged after the last row (the rows stop at Ctrl-C; the executor logs until
    it has stopped). ``summarised``: the plans the summary counts (real time: those the executor adopted,
    :mod:`services.adopted_plans`; the others were never executed, and `foresight log table` leaves them out as the
    summary does: it said it printed every one, and printed 23 of 29; a review).
    """
    if not mcap.is_file():
        return "no log was written (the executor ended before it opened one, or had not started)"
    from shared.recording.reader import read_log

    try:
        lf = read_log(mcap)
    except UserError as exc:  # an empty file (a full disk as the executor opened it): the run's end is still said
        return f"log {mcap}: unreadable, no message in it ({exc})"
    text = f"log {mcap}: {lf.state}, {lf.message_count} messages"
    if plan_topic is not None:
        logged = sum(c.count for c in lf.channels.values() if c.topic == plan_topic)
        late = received - logged
        closed = "came after the executor closed it" if lf.complete else "are not in it: it ends before them"
        counted = (f"; the summary and `foresight log table {mcap}` count the {summarised} the executor adopted, "
                   "the others were never executed" if summarised is not None and summarised < logged
                   else f": `foresight log table {mcap}` prints every one")
        text += f", {logged} plans" + (f" (the last {late} {closed})" if late > 0 else
                                       f" ({-late} after the rows above, made while the executor stopped{counted})"
                                       if late < 0 else "")
    return text


def unexecuted(k: int) -> str:
    """Why ``k`` rows of a real-time run's table are not in its summary."""
    rows, them = ("one row above was a plan", "it") if k == 1 else (f"{k} rows above were plans", "them")
    return (f"{rows} the executor never adopted (overtaken by a newer plan before its next state, or made as the "
            f"run ended): the summary leaves {them} out")


class Lines:
    """Lines printed by a thread of their own, in the order given (a context manager: its exit prints the rest).

    The table's rows are printed from a Zenoh callback: a terminal that does not read (``foresight demo | less``
    left unscrolled) blocked that callback, and with it every service's publisher (they block on congestion): the
    whole run froze. Now only this thread waits for the terminal.
    """

    def __init__(self, out: Callable[[str], None]) -> None:
        self._queue: queue.SimpleQueue[str | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._print, args=(out,), name="demo-lines", daemon=True)

    def __call__(self, line: str) -> None:
        """Queue ``line``; it is printed in turn (never waits for the terminal)."""
        self._queue.put(line)

    def _print(self, out: Callable[[str], None]) -> None:
        printing = True
        while (line := self._queue.get()) is not None:
            if not printing:
                continue  # the lines still come; nobody reads them
            try:
                out(line)
            except OSError:  # `foresight demo | head -3`: the reader left (EPIPE); the run goes on, its log whole
                printing = False  # (it was a traceback of this thread, and the run went on regardless)

    def __enter__(self) -> Lines:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._queue.put(None)
        self._thread.join()
