"""Progress bars: tqdm's in-place bar on a terminal, whole lines in a log (shared/progress.py)."""

from __future__ import annotations

import io

from shared.progress import progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_gets_whole_lines_not_carriage_returns() -> None:
    """`make demo > demo.log`: each bar was one line of every frame joined by carriage returns."""
    log = io.StringIO()
    assert list(progress(range(8), desc="GMM per class", unit="class", file=log)) == list(range(8))
    text = log.getvalue()
    lines = text.splitlines()
    assert "\r" not in text and lines and all(ln.startswith("GMM per class:") for ln in lines)
    assert "8/8" in lines[-1] and len(lines) <= 3  # the first, the last (and one more within 5 s at most)


def test_a_terminal_gets_the_bar_in_place_and_disabled_is_silent() -> None:
    tty = _Terminal()
    list(progress(iter(range(3)), desc="leave-one-out", unit="demo", total=3, file=tty))
    assert "\r" in tty.getvalue() and "3/3" in tty.getvalue()
    quiet = io.StringIO()
    assert list(progress([1, 2], desc="x", unit="y", enabled=False, file=quiet)) == [1, 2] and not quiet.getvalue()
