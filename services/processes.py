"""Run Foresight services as separate processes: start, wait for liveliness, stop within bounds."""

from __future__ import annotations

import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from shared.runtime import PARENT_ENV, UserError

__all__ = ["ServiceProcess", "free_port"]

log = logging.getLogger("foresight.processes")


def describe_exit(code: int | None) -> str:
    """``-9`` -> ``"was killed (SIGKILL)"``, ``1`` -> ``"exited with status 1"``."""
    if code is not None and code < 0:
        try:
            return f"was killed ({signal.Signals(-code).name})"
        except ValueError:
            return f"was killed (signal {-code})"
    return f"exited with status {code}"


class ServiceProcess:
    """One Foresight service run as ``python -m MODULE ARGS`` in its own process.

    Output (stdout and stderr) goes to ``log_path``. :meth:`stop` sends SIGTERM, waits up to a
    bounded time, then kills.

    The process runs in its own process group, so a terminal's Ctrl-C (SIGINT to the foreground
    group) reaches only the parent, which stops its services once each, in its own order (the
    executor first, which closes the MCAP). It starts with SIGINT blocked: a Ctrl-C in the instant
    it is forked, while still in the parent's group, is held, not fatal, and its service drops it
    as it installs its handlers (:func:`shared.stopping.stop_on_signals`). Should the parent die
    without stopping them, each service sees it (:data:`shared.runtime.PARENT_ENV` names the
    parent's pid; :func:`shared.runtime.watch_parent`) and stops by itself.

    Args:
        name: Service name; also the liveliness token it declares (``<prefix>/alive/<name>``).
        module: Module run with ``python -m``, e.g. ``services.replayer``.
        args: Command-line arguments (typically including ``--connect <router endpoint>``).
        log_path: File receiving the process's output.
        env: Extra environment variables.
    """

    def __init__(self, name: str, module: str, args: list[str], log_path: Path,
                 env: dict[str, str] | None = None) -> None:
        self.name = name
        self.module = module
        self.args = list(args)
        self.log_path = Path(log_path)
        self.env = dict(env or {})
        self.proc: subprocess.Popen[bytes] | None = None
        self._log_from = 0

    @property
    def command(self) -> list[str]:
        """The full command line."""
        return [sys.executable, "-m", self.module, *self.args]

    def start(self) -> ServiceProcess:
        """Start the process (returns self)."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        again = self.proc is not None  # a restart: the log of the run that ended (its crash) is kept above
        with self.log_path.open("ab" if again else "wb") as out:
            if again:
                out.write(f"\n--- {self.name} started again (the run above exited with status "
                          f"{self.proc.returncode}) ---\n".encode())
                out.flush()
            self._log_from = out.tell()  # this run's output starts here (tail reads no earlier run's, nor the banner)
            # the child leaves this process's group only once forked (Popen's setpgid, just before exec): a Ctrl-C to
            # the group in between reached it too and killed it ("replayer exited with status -2" after Ctrl-C at
            # "planner up"). Forked with SIGINT blocked, it holds that one and drops it (shared.stopping)
            held = signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGINT])
            try:
                self.proc = subprocess.Popen(self.command, stdout=out, stderr=subprocess.STDOUT,
                                             stdin=subprocess.DEVNULL, process_group=0,
                                             env={**os.environ, "PYTHONUNBUFFERED": "1", PARENT_ENV: str(os.getpid()),
                                                  **self.env})
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, held)
        log.info("started %s (pid %d): %s", self.name, self.proc.pid, " ".join(self.command))
        return self

    @property
    def running(self) -> bool:
        """Whether the process has been started and not yet exited."""
        return self.proc is not None and self.proc.poll() is None

    @property
    def returncode(self) -> int | None:
        """Exit status once exited, else None."""
        return None if self.proc is None else self.proc.poll()

    def tail(self, lines: int = 3) -> str:
        """The last lines of the process's output since its latest start ('' when it printed nothing)."""
        try:
            with self.log_path.open("rb") as f:
                f.seek(self._log_from)
                text = f.read().decode(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.strip().splitlines()[-lines:])

    def last_words(self) -> str:
        """The last output line of a process that exited by itself with an error status.

        '' otherwise: while it runs, after status 0, or when a signal ended it (its log's last line is then no reason).
        """
        code = self.returncode
        return self.tail(1) if code is not None and code > 0 else ""

    def wait_alive(self, is_alive: Callable[[str], bool], timeout: float,
                   stop: threading.Event | None = None) -> bool:
        """Wait until the service's liveliness token is seen.

        Args:
            is_alive: E.g. :meth:`shared.transport.Presence.is_alive`.
            timeout: Seconds.
            stop: Set by the caller's stop request (Ctrl-C): stop waiting.

        Returns:
            True once the service is alive, False when ``stop`` was set first.

        Raises:
            UserError: If the process exits first (with its last output line) or the timeout passes.
        """
        deadline = time.monotonic() + timeout
        while not is_alive(self.name):
            if stop is not None and stop.is_set():
                return False
            if not self.running:
                why = self.last_words()
                raise UserError(f"{self.name} {describe_exit(self.returncode)}" + (f": {why}" if why else ""))
            if time.monotonic() > deadline:
                raise UserError(f"{self.name} did not come up within {timeout:g} s (see {self.log_path})")
            time.sleep(0.02)
        return True

    def stop(self, timeout: float = 5.0, kill_wait: float = 5.0) -> int | None:
        """SIGTERM, wait up to ``timeout`` s, then SIGKILL and wait up to ``kill_wait`` s; returns the exit status.

        None when it has not ended even then (a process in uninterruptible sleep, ``D``, outlives SIGKILL until its
        I/O returns): said in one warning, not raised, so that a caller stopping several goes on to the next.
        """
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.send_signal(signal.SIGCONT)  # a stopped (SIGSTOP, Ctrl-Z) process holds SIGTERM until it runs
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop within %g s: killing it", self.name, timeout)
                self.proc.kill()
                try:
                    self.proc.wait(timeout=kill_wait)
                except subprocess.TimeoutExpired:
                    log.warning("%s (pid %d) outlived SIGKILL by %g s (uninterruptible I/O?): left to end by itself",
                                self.name, self.proc.pid, kill_wait)
        return self.proc.poll()

    def __enter__(self) -> ServiceProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def free_port() -> int:
    """A currently free TCP port on 127.0.0.1."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
