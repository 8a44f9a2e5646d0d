"""A real-time run as separate processes (router + four services) and a watcher of what it publishes.

What ``foresight bench faults`` and ``foresight bench soak`` (and their tests) drive: every process
runs as ``python -m ...`` on loopback, connected to a ``foresight router`` on a free port, multicast
scouting off; :meth:`ProcessSystem.close` stops every process with a bounded timeout. The
:class:`Watcher` is a Zenoh session of the calling process that records, with their monotonic
arrival time, the robot's states, the poses, the occupancy grids, the plans and the services'
liveliness tokens.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path

from services.processes import ServiceProcess, free_port
from shared.config import ZenohConfig, endpoint_host_port
from shared.protocol import HumanPose, Keys, OccupancyGrid, Plan, RobotState
from shared.runtime import UserError
from shared.transport import Presence, open_session, subscribe

__all__ = ["SystemSpec", "ProcessSystem", "Watcher", "rss_mb", "peak_rss_mb", "positive_number", "SERVICES",
           "PROCESSES"]

SERVICES = ("predictor", "planner", "replayer", "executor")
PROCESSES = ("router", *SERVICES)
"""Every process of the system: what ``foresight bench faults --victims`` may name."""


def positive_number(low: float = 0.0, high: float = math.inf, inclusive: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite number above ``low`` (or equal to it with ``inclusive``) and at most ``high``."""
    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not (math.isfinite(x) and (low <= x if inclusive else low < x) and x <= high):
            bound = f"{'>=' if inclusive else '>'} {low:g}" + (f" and <= {high:g}" if high < math.inf else "")
            raise argparse.ArgumentTypeError(f"{text!r}: must be a finite number {bound}")
        return x
    return parse


def _status_mb(pid: int, key: str) -> float | None:
    """A memory line (``VmRSS``, ``VmHWM``) of ``/proc/PID/status`` in MB; None when the process is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(f"{key}:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def rss_mb(pid: int) -> float:
    """Resident memory of process ``pid`` in MB (0 when it is gone)."""
    mb = _status_mb(pid, "VmRSS")
    return 0.0 if mb is None else mb


def peak_rss_mb(pid: int) -> float:
    """A live process's peak resident memory (``VmHWM``) in MB; NaN when it is gone."""
    mb = _status_mb(pid, "VmHWM")
    return float("nan") if mb is None else mb


@dataclasses.dataclass
class SystemSpec:
    """What to run.

    Attributes:
        run_dir: Service logs and the MCAP go here.
        model: Prediction model file.
        library: Library the replayer loops over (None: the embedded synthetic one).
        rate_hz: Poses per second.
        period_s: The planner's replanning period.
        stale_limit_s: The executor's stale limit.
        mcap: Write the executor's MCAP (``run_dir/run.mcap``).
    """

    run_dir: Path
    model: Path
    library: Path | None = None
    rate_hz: float = 30.0
    period_s: float = 0.2
    stale_limit_s: float = 0.5
    mcap: bool = True

    @property
    def mcap_path(self) -> Path:
        """The executor's log."""
        return self.run_dir / "run.mcap"


class ProcessSystem:
    """Router and services as processes; start, kill, restart, stop (bounded)."""

    def __init__(self, spec: SystemSpec) -> None:
        self.spec = spec
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        spec.run_dir.mkdir(parents=True, exist_ok=True)
        common = ["--connect", self.endpoint, "--listen", "tcp/127.0.0.1:0", "--log-level", "INFO"]
        lib = ["--library", str(spec.library)] if spec.library else []
        self.args: dict[str, tuple[str, list[str]]] = {
            "router": ("tools", ["router", "--listen", self.endpoint]),
            "predictor": ("services.predictor", ["--model", str(spec.model), *common]),
            "planner": ("services.planner", ["--mode", "realtime", "--period-s", str(spec.period_s),
                                             "--lookahead-s", str(spec.period_s), *common]),
            "replayer": ("services.replayer", [*lib, "--loop", "--rate-hz", str(spec.rate_hz), "--wait-for",
                                               "executor", *common]),
            "executor": ("services.executor", ["--mode", "realtime", "--steps", "0", "--stale-limit-s",
                                               str(spec.stale_limit_s), "--mcap",
                                               str(spec.mcap_path) if spec.mcap else "none", *common]),
        }
        self.procs: dict[str, ServiceProcess] = {}
        self.starts: dict[str, int] = {}
        self.mcap_path = spec.mcap_path
        """The MCAP the executor now running writes (``run-<n>.mcap`` after the n-th restart)."""

    def start(self, name: str) -> ServiceProcess:
        """Start (or start again) one process.

        Its log is ``run_dir/<name>[-<n>].log``; the executor started again writes ``run_dir/run-<n>.mcap``, so
        that every run's record is kept.
        """
        n = self.starts.get(name, 0)
        self.starts[name] = n + 1
        module, args = self.args[name]
        if name == "executor" and n > 0 and self.spec.mcap:  # its own log: opening run.mcap again would empty it
            self.mcap_path = self.spec.run_dir / f"run-{n}.mcap"
            args = [str(self.mcap_path) if a == str(self.spec.mcap_path) else a for a in args]
        log = self.spec.run_dir / (f"{name}.log" if n == 0 else f"{name}-{n}.log")
        self.procs[name] = ServiceProcess(name, module, args, log).start()
        return self.procs[name]

    def start_all(self) -> None:
        """The router, then the services (the executor last)."""
        self.start_router()
        self.start_services()

    def start_router(self, timeout: float = 30.0) -> None:
        """Start the router and wait until it takes connections (a watcher opened before it warned it was unreachable).

        Raises:
            UserError: The router exited, or took no connection within ``timeout`` s.
        """
        router = self.start("router")
        host, port = endpoint_host_port(self.endpoint)
        deadline = time.monotonic() + timeout
        while True:
            try:
                socket.create_connection((host, port), timeout=0.5).close()
                return
            except OSError:
                if not router.running or time.monotonic() > deadline:
                    raise UserError(f"the router on {self.endpoint} did not take connections "
                                    f"(see {router.log_path})") from None
                time.sleep(0.05)

    def start_services(self) -> None:
        """The services, the executor last (the router first: :meth:`start_router`)."""
        for name in SERVICES:
            self.start(name)

    def kill(self, name: str) -> None:
        """SIGKILL one process and reap it."""
        proc = self.procs[name].proc
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)

    def rss(self) -> dict[str, float]:
        """Resident memory (MB) of every running process."""
        return {n: rss_mb(p.proc.pid) for n, p in self.procs.items() if p.running and p.proc is not None}

    def exited(self) -> dict[str, int]:
        """The processes that have exited, with their exit statuses."""
        return {n: p.returncode for n, p in self.procs.items() if p.returncode is not None}

    def wait_moving(self, watcher: Watcher, timeout: float, before: str = "") -> None:
        """Wait until the robot moves; stop waiting as soon as a process has exited.

        Raises:
            UserError: The robot did not move within ``timeout`` s, or a process exited first; the message
                names the processes that exited, their last log line, and where the logs are.
        """
        watcher.wait(lambda: watcher.moving() or bool(self.exited()), timeout)
        if watcher.moving() and not self.exited():
            return
        gone = self.exited()
        why = "; ".join(f"{n} exited with status {c} ({self.procs[n].tail(1) or 'no output'})"
                        for n, c in gone.items()) if gone else f"the robot did not move within {timeout:g} s"
        raise UserError(f"{why}{before}; the logs are in {self.spec.run_dir}")

    def close(self, timeout: float = 15.0) -> dict[str, int | None]:
        """Stop everything (SIGTERM, then SIGKILL after ``timeout``); returns the exit statuses."""
        codes = {}
        for name in ("executor", "replayer", "planner", "predictor", "router"):
            if name in self.procs:
                codes[name] = self.procs[name].stop(timeout=timeout)
        return codes


class Watcher:
    """Records the run's states, poses, occupancy grids, plans and liveliness changes as they arrive.

    Each list holds ``(monotonic arrival, message)``; ``tokens`` holds ``(arrival, service, alive)``.
    """

    def __init__(self, endpoint: str, poses: bool = False) -> None:
        self.cfg = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint])
        self.keys = Keys(self.cfg.prefix)
        self.states: list[tuple[float, RobotState]] = []
        self.occupancy: list[tuple[float, OccupancyGrid]] = []
        self.plans: list[tuple[float, Plan]] = []
        self.poses: list[tuple[float, HumanPose]] = []
        self.tokens: list[tuple[float, str, bool]] = []
        self._poses = poses
        self.wall_offset = time.time() - time.monotonic()  # wall stamp - offset = this process's monotonic time
        self._ctx = open_session(self.cfg, name="watcher")
        self._lock = threading.Lock()

    def _rec(self, items: list) -> Callable[[object], None]:
        def put(msg: object) -> None:
            with self._lock:
                items.append((time.monotonic(), msg))
        return put

    def __enter__(self) -> Watcher:
        session = self._ctx.__enter__()
        k = self.keys
        self._subs: list = []
        self.presence: Presence | None = None
        try:  # a failed declaration closes what was opened (the session above all)
            wanted = [(k.robot_state, RobotState, self.states), (k.occupancy, OccupancyGrid, self.occupancy),
                      (k.plan, Plan, self.plans)] + ([(k.pose, HumanPose, self.poses)] if self._poses else [])
            for key, kind, items in wanted:
                self._subs.append(subscribe(session, key, kind, self._rec(items)))
            self.presence = Presence(session, k, "watcher", on_change=self._token)
        except BaseException:
            self.__exit__()
            raise
        return self

    def _token(self, service: str, alive: bool) -> None:
        with self._lock:
            self.tokens.append((time.monotonic(), service, alive))

    def __exit__(self, *exc: object) -> None:
        try:
            if self.presence is not None:
                self.presence.close()
            for s in self._subs:
                s.undeclare()
        finally:
            self._ctx.__exit__(None, None, None)

    def snapshot(self, items: list) -> list:
        """A copy of one of the lists."""
        with self._lock:
            return list(items)

    def wait(self, pred: Callable[[], bool], timeout: float, poll: float = 0.02) -> bool:
        """Wait until ``pred()`` holds (at most ``timeout`` s)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if pred():
                return True
            time.sleep(poll)
        return False

    def moving(self) -> bool:
        """Whether the robot's latest state is not holding."""
        with self._lock:
            return bool(self.states) and not self.states[-1][1].holding
