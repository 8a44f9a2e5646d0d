"""The demo's run directories: one per run under ``runs/demo/``, and ``latest`` pointing to the newest that ran.

Each run gets ``<UTC stamp>-<mode>[-compare]`` (``-2``, ``-3`` for runs within one second). ``latest`` points to a
run once its services start, so that their logs can be followed during the run; a run interrupted before it wrote an
MCAP log hands ``latest`` back to the run it pointed to before (the README's ``foresight log info
runs/demo/latest`` found nothing after an early Ctrl-C), and a run no service wrote into is removed. The first run
(``latest`` pointed nowhere before) keeps it while its service logs are kept: ``latest`` then points to a run without
an MCAP log, on purpose, its logs being all there is to look at. Such a run's last line names its directory and what
``latest`` points to (:meth:`RunDirectory.whereabouts`).
"""

from __future__ import annotations

import itertools
import shutil
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from services.processes import ServiceProcess

__all__ = ["RunDirectory", "variant_dir", "compare_log", "log_state", "describe_log", "log_incomplete",
           "forced_exit_note", "stop_service", "MAIN_VARIANT"]

MAIN_VARIANT = "prediction"
"""The planner a ``--compare`` run is about (the paper's method; ``services.demo.VARIANTS``' first)."""


def variant_dir(name: str) -> str:
    """A ``--compare`` planner's directory in its run's (``current occupancy`` -> ``current-occupancy``)."""
    return name.replace(" ", "-")


def compare_log(directory: Path) -> Path | None:
    """The log a ``--compare`` run's directory stands for: its prediction run's; None for any other directory.

    The README's ``foresight log table runs/demo/latest`` after ``--compare`` (three logs under it) said only that
    the path is a directory (a new user's run).
    """
    logs = sorted(directory.rglob("*.mcap")) if directory.is_dir() else []
    main = [f for f in logs if f.parent == directory / variant_dir(MAIN_VARIANT)]
    return main[0] if len(logs) > 1 and len(main) == 1 and all(f.parent.parent == directory for f in logs) else None


def log_state(mcap: str | Path) -> str:
    """An MCAP log's state as every tool names it: ``complete`` (the executor finalised it), ``TRUNCATED (...)``."""
    from shared.recording.reader import read_log  # the MCAP reader: only for a run that says it
    from shared.runtime import UserError

    try:
        return read_log(mcap).state
    except UserError as exc:  # not an MCAP at all (an empty file: the executor died as it opened it)
        return f"unreadable: {exc}"


def describe_log(path: str | None, interrupted: bool = False, said: str = "") -> str:
    """The demo's ``MCAP log:`` entry: the path, and what is wrong with the log where it is not complete.

    A full disk lost half a run's log while the demo printed the usual lines (a review): now ``PATH — INCOMPLETE:
    N of M messages written (why)`` from the executor's own line (``said``), or the reader's state where it said
    nothing (a log without its footer). After an interrupt, the state in any case: ``PATH (complete)``.
    """
    if not path or not Path(path).is_file():
        return str(path)
    if interrupted:
        return f"{path} ({log_state(path)})"
    if said:
        return f"{path} — INCOMPLETE: {said.split('INCOMPLETE: ', 1)[-1]}"
    from shared.recording.reader import ends_finished

    return str(path) if ends_finished(path) else f"{path} — INCOMPLETE: {log_state(path)}"  # whole: nothing read


def log_incomplete(executor: ServiceProcess | None) -> dict[str, str]:
    """The summary's ``log_incomplete`` entry when the executor ended with its log incomplete, else ``{}``.

    Its value is the executor's last ``mcap:`` line (``PATH: INCOMPLETE: N of M messages written (why)``), said after
    its status :data:`~services.executor.result.LOG_INCOMPLETE`.
    """
    from services.executor.result import LOG_INCOMPLETE

    if executor is None or executor.returncode != LOG_INCOMPLETE:
        return {}
    said = [line for line in executor.tail(20).splitlines() if line.startswith("mcap: ") and "INCOMPLETE" in line]
    return {"log_incomplete": said[-1].removeprefix("mcap: ") if said else "the executor said its log is incomplete"}


def forced_exit_note(run: Path) -> str:
    """What the demo's forced exit (a second Ctrl-C while it stops) adds to its one line: where the run's files are.

    That line was the demo's last (``make: *** ... Error 3`` after it), naming neither the run's directory nor its
    MCAP log, which was complete: each service runs in a process group of its own and stops by itself once it sees
    its parent gone, the executor finalising the log as it does (a new user's first hour).
    """
    return (f"this run's files: {run}/; its services stop on their own (each sees the demo gone) and the executor "
            f"finishes the MCAP log: check it with `foresight log info {run}`")


def stop_service(proc: ServiceProcess, timeout: float, kill_wait: float = 5.0) -> int | None:
    """Stop ``proc`` (:meth:`ServiceProcess.stop`); one stopped before it wrote anything gets a line in its log.

    SIGTERM while a service still imports ends it before its handlers exist: its log in the run's directory was
    empty, unexplained beside the planner's "stopped while starting" (Ctrl-C during a new user's first start-up).
    """
    from services.processes import describe_exit

    running = proc.running
    code = proc.stop(timeout=timeout, kill_wait=kill_wait)
    if running and code is not None and not proc.tail(1):
        try:
            with proc.log_path.open("a") as log:
                log.write(f"{proc.name} {describe_exit(code)}: stopped by foresight demo before it had started "
                          "(SIGTERM while it was still importing, before its signal handlers)\n")
        except OSError:  # a full disk: the log stays empty, the stop goes on
            pass
    return code


@dataclass
class RunDirectory:
    """One demo run's directory and the ``latest`` link beside it.

    Attributes:
        path: The run's directory.
        previous_: What ``latest`` pointed to before :meth:`point_latest` (None: nothing, or not yet pointed).
    """

    path: Path
    previous_: str | None = None

    @classmethod
    def create(cls, root: Path, mode: str, compare: bool) -> RunDirectory:
        """A new directory under ``root`` named for the time (UTC), ``mode`` and ``compare``."""
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        name = f"{stamp}-{mode}{'-compare' if compare else ''}"
        root.mkdir(parents=True, exist_ok=True)
        for n in itertools.count(1):  # two runs within a second: made, not checked then made (two demos raced)
            run = root / (name if n == 1 else f"{name}-{n}")
            try:
                run.mkdir()
            except FileExistsError:
                continue
            return cls(run)
        raise AssertionError("unreachable")  # pragma: no cover

    @property
    def latest(self) -> Path:
        """The ``latest`` link beside the run."""
        return self.path.parent / "latest"

    def point_latest(self) -> None:
        """``latest`` points to this run (called as its services start: a failed start leaves it as it was)."""
        try:
            if self.latest.is_symlink() or not self.latest.exists():
                before = str(self.latest.readlink()) if self.latest.is_symlink() else None
                if before == self.path.name:  # pointed already (--compare: each planner's services start)
                    return
                self.previous_ = before
                self.latest.unlink(missing_ok=True)
                self.latest.symlink_to(self.path.name, target_is_directory=True)
        except OSError:  # a file system without symlinks: the directory names still sort by time
            pass

    def has_log(self) -> bool:
        """Whether an MCAP log was written under the run."""
        return any(p.suffix == ".mcap" for p in self.path.rglob("*"))

    def end_without_log(self) -> None:
        """The run ended before writing a log: ``latest`` goes back to the run before; an empty directory goes."""
        try:
            ours = self.latest.is_symlink() and self.latest.readlink().name == self.path.name
        except OSError:
            ours = False
        if self.path.is_dir() and not any(p.suffix in (".log", ".mcap") for p in self.path.rglob("*")):
            shutil.rmtree(self.path, ignore_errors=True)
        if not ours or (self.previous_ is None and self.path.exists()):
            return  # not ours to move; or a first run's service logs, which it may as well point to
        try:
            self.latest.unlink()
            if self.previous_ is not None:
                self.latest.symlink_to(self.previous_, target_is_directory=True)
        except OSError:
            pass

    def whereabouts(self) -> str | None:
        """Where a run that ended without a summary left its files and what ``latest`` points to; None: nothing kept.

        After a Ctrl-C before the first plan nothing named the run's directory, and ``latest`` had gone back to the
        run before: the interrupted run's service logs were to be found by their time (a new user's first hour).
        """
        if not self.path.is_dir():
            return None
        logs = sorted(self.path.rglob("*.mcap"))
        kept = ("its services' logs and " + ", ".join(f"MCAP log {p.name} ({log_state(p)})" for p in logs) if logs
                else "its services' logs, no MCAP log (the executor had not opened one)")
        try:
            target = self.latest.readlink().name if self.latest.is_symlink() else None
        except OSError:
            target = None
        link = (f"{self.latest} points to it" if target == self.path.name else
                f"{self.latest} still points to {target}, the run before (a run without an MCAP log hands it back)"
                if target else f"no {self.latest} link")
        return f"this run's files: {self.path}/: {kept}; {link}"
