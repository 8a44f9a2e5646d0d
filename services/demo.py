"""``foresight demo`` (``make demo``): run what exists of the system on this machine and show it live.

The demo session itself is the Zenoh router (router mode, listening on a loopback port); each
service runs as its own process (``python -m services.<name> --connect <router>``), started and
stopped by :class:`ServiceProcess`. For now only the replayer exists as a service: the demo streams
a few demonstrations, prints a live summary of what arrives, and says which parts are not there yet.
Service logs go to ``runs/demo/<service>.log``.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
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

from services.replayer.core import ReplayerConfig, load_replay_library
from shared.config import ConfigError, ZenohConfig, add_config_arguments, opt, resolve_config
from shared.protocol import DemoMarker, HumanPose, Keys, Message
from shared.runtime import UserError, cli_errors, setup_logging, stop_on_signals
from shared.transport import Presence, open_session, subscribe_ordered

__all__ = ["DemoConfig", "ServiceProcess", "StreamMonitor", "main", "PENDING_PARTS"]

log = logging.getLogger("foresight.demo")

# part -> (module run as a service, the issue that brings it, what is missing without it)
PENDING_PARTS: dict[str, tuple[str, int, str]] = {
    "predictor": ("services.predictor", 3, "nothing recognises the motion or predicts the occupancy"),
    "planner": ("services.planner", 4, "nothing plans robot motion"),
    "executor": ("services.executor", 5, "nothing moves the simulated PR2 or logs the run"),
}


@dataclasses.dataclass
class DemoConfig:
    """Options of ``foresight demo`` (``[demo]`` in the TOML file)."""

    library: Path | None = opt(None, help="motion library (directory of compound_*.csv or .npz); unset = the "
                                    "embedded synthetic library")
    demos: int = opt(3, help="number of demonstrations to stream")
    rate_hz: float = opt(30.0, help="replay rate (poses per second)")
    seed: int = opt(0, help="seed of the demonstration order (and of the synthetic library)")
    port: int = opt(0, help="loopback TCP port of the demo's Zenoh router (0 = a free port)")
    prefix: str = opt("foresight", help="key-expression prefix")
    timeout: float = opt(120.0, help="stop everything after this many seconds")
    run_dir: Path = opt(Path("runs/demo"), help="directory for the services' log files")
    log_level: str = opt("WARNING", choices=("DEBUG", "INFO", "WARNING", "ERROR"), help="log level of the demo")

    def validate(self) -> None:
        """Check value ranges."""
        if self.demos < 1:
            raise ConfigError(f"demo.demos: must be >= 1, got {self.demos}")
        if not self.rate_hz > 0:
            raise ConfigError(f"demo.rate_hz: must be > 0, got {self.rate_hz}")
        if not 0 <= self.port < 65536:
            raise ConfigError(f"demo.port: must be 0..65535, got {self.port}")
        if not self.timeout > 0:
            raise ConfigError(f"demo.timeout: must be > 0, got {self.timeout}")


# ----------------------------------------------------------------------------------------------
# process management (reused by later demos: predictor, planner, executor)


class ServiceProcess:
    """One Foresight service run as ``python -m MODULE ARGS`` in its own process.

    Output (stdout and stderr) goes to ``log_path``. :meth:`stop` sends SIGTERM, waits up to a
    bounded time, then kills.

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

    @property
    def command(self) -> list[str]:
        """The full command line."""
        return [sys.executable, "-m", self.module, *self.args]

    def start(self) -> ServiceProcess:
        """Start the process (returns self)."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with self.log_path.open("wb") as out:
            self.proc = subprocess.Popen(self.command, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                         env={**os.environ, "PYTHONUNBUFFERED": "1", **self.env})
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
        """The last lines of the process's output."""
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.strip().splitlines()[-lines:])

    def wait_alive(self, is_alive: Callable[[str], bool], timeout: float) -> None:
        """Wait until the service's liveliness token is seen.

        Args:
            is_alive: E.g. :meth:`shared.transport.Presence.is_alive`.
            timeout: Seconds.

        Raises:
            UserError: If the process exits first (with its last output line) or the timeout passes.
        """
        deadline = time.monotonic() + timeout
        while not is_alive(self.name):
            if not self.running:
                raise UserError(f"{self.name} exited with status {self.returncode}: {self.tail(1)}")
            if time.monotonic() > deadline:
                raise UserError(f"{self.name} did not come up within {timeout:g} s (see {self.log_path})")
            time.sleep(0.02)

    def stop(self, timeout: float = 5.0) -> int | None:
        """SIGTERM, wait up to ``timeout`` s, then SIGKILL; returns the exit status."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop within %g s: killing it", self.name, timeout)
                self.proc.kill()
                self.proc.wait(timeout=5.0)
        return self.proc.returncode

    def __enter__(self) -> ServiceProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def free_port() -> int:
    """A currently free TCP port on 127.0.0.1."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ----------------------------------------------------------------------------------------------
# live summary


@dataclasses.dataclass
class _DemoState:
    demo_id: int
    class_name: str
    true_class: int
    n_samples: int
    received: int = 0
    first: float | None = None
    last: float | None = None
    ended: bool = False

    def rate(self) -> float:
        if self.first is None or self.last is None or self.received < 2 or self.last <= self.first:
            return 0.0
        return (self.received - 1) / (self.last - self.first)


class StreamMonitor:
    """Turns the replayer's poses and markers into summary lines (thread-safe, no Zenoh).

    Args:
        clock: Time source for rates (seconds).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self.demos: dict[int, _DemoState] = {}
        self.current: int | None = None
        self.lines: list[str] = []
        self.total_poses = 0
        self.stray_poses = 0

    def on_message(self, msg: Message) -> None:
        """Feed one received message."""
        now = self._clock()
        with self._lock:
            if isinstance(msg, DemoMarker):
                if msg.event == "start":
                    self.demos[msg.demo_id] = _DemoState(msg.demo_id, msg.class_name, msg.true_class, msg.n_samples)
                    self.current = msg.demo_id
                    self.lines.append(f"demo {msg.demo_id}: start, class {msg.true_class} ({msg.class_name}), "
                                      f"{msg.n_samples} samples")
                else:
                    st = self.demos.get(msg.demo_id)
                    if st is not None:
                        st.ended = True
                        self.lines.append(f"demo {msg.demo_id}: end, received {st.received}/{st.n_samples} poses "
                                          f"at {st.rate():.1f} Hz")
            elif isinstance(msg, HumanPose):
                self.total_poses += 1
                st = self.demos.get(msg.demo_id)
                if st is None:
                    self.stray_poses += 1
                    return
                st.received += 1
                st.first = now if st.first is None else st.first
                st.last = now

    def progress(self) -> str | None:
        """One line on the demonstration in progress (None if none is)."""
        with self._lock:
            st = self.demos.get(self.current) if self.current is not None else None
            if st is None or st.ended:
                return None
            return f"demo {st.demo_id}: {st.received}/{st.n_samples} poses, {st.rate():.1f} Hz"

    def take_lines(self) -> list[str]:
        """Event lines since the last call."""
        with self._lock:
            out, self.lines = self.lines, []
            return out

    @property
    def finished(self) -> int:
        """Number of demonstrations whose end marker arrived."""
        with self._lock:
            return sum(st.ended for st in self.demos.values())


def pending_parts() -> list[str]:
    """Plain statements about the parts this interim demo does not run."""
    out = []
    for part, (module, issue, missing) in PENDING_PARTS.items():
        if importlib.util.find_spec(f"{module}.__main__") is None:
            out.append(f"{part}: not implemented yet (issue {issue}): {missing}")
        else:
            out.append(f"{part}: exists ({module}) but this interim demo does not start it yet (issue 5): {missing}")
    return out


# ----------------------------------------------------------------------------------------------
# main


def run_demo(cfg: DemoConfig, stop: threading.Event, out: Callable[[str], None] = print) -> int:
    """Run the demo until the demonstrations are streamed, ``cfg.timeout`` passes or ``stop`` is set."""
    lib = load_replay_library(ReplayerConfig(library=cfg.library, seed=cfg.seed))  # fail early, one line
    port = cfg.port or free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    keys = Keys(cfg.prefix)
    out(f"foresight demo: library {lib.source}: {lib.n_classes} classes, {len(lib.demos)} demonstrations"
        + (f" ({len(lib.issues)} malformed left out)" if lib.issues else ""))
    out(f"foresight demo: router on {endpoint}; service logs in {cfg.run_dir}/")
    replayer_args = ["--rate-hz", str(cfg.rate_hz), "--max-demos", str(cfg.demos), "--shuffle", "--seed",
                     str(cfg.seed), "--wait-for", "monitor", "--connect", endpoint, "--listen", "tcp/127.0.0.1:0",
                     "--prefix", cfg.prefix, "--zenoh-mode", "peer"]
    if cfg.library is not None:
        replayer_args += ["--library", str(cfg.library)]
    monitor = StreamMonitor()
    hub = ZenohConfig(mode="router", listen=[endpoint], connect=[], multicast_scouting=False, prefix=cfg.prefix)
    deadline = time.monotonic() + cfg.timeout
    status = 0
    with open_session(hub) as session:
        sub = subscribe_ordered(session, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker},
                                monitor.on_message)
        presence = Presence(session, keys, "monitor")
        replayer = ServiceProcess("replayer", "services.replayer", replayer_args, cfg.run_dir / "replayer.log")
        try:
            replayer.start()
            replayer.wait_alive(presence.is_alive, timeout=min(30.0, cfg.timeout))
            out("foresight demo: replayer up, streaming")
            last_progress = 0.0
            while not stop.is_set():
                for line in monitor.take_lines():
                    out(line)
                if monitor.finished >= cfg.demos:
                    break
                if not replayer.running:
                    stop.wait(0.5)  # let the last messages arrive
                    for line in monitor.take_lines():
                        out(line)
                    if monitor.finished < cfg.demos:
                        out(f"foresight demo: replayer exited (status {replayer.returncode}) after "
                            f"{monitor.finished}/{cfg.demos} demonstrations: {replayer.tail(1)}")
                        status = 1
                    break
                if time.monotonic() > deadline:
                    out(f"foresight demo: timeout after {cfg.timeout:g} s")
                    status = 1
                    break
                now = time.monotonic()
                if now - last_progress >= 1.0:
                    line = monitor.progress()
                    if line:
                        out(line)
                    last_progress = now
                stop.wait(0.05)
            if stop.is_set():
                out("foresight demo: interrupted")
        finally:
            code = replayer.stop(timeout=5.0)
            presence.close()
            sub.undeclare()
    out(f"foresight demo: {monitor.finished} demonstrations, {monitor.total_poses} poses received; "
        f"replayer exit status {code}")
    out("not there yet:")
    for line in pending_parts():
        out(f"  {line}")
    return status


def main(argv: list[str] | None = None, prog: str = "foresight demo") -> int:
    """Run the interim demo; returns 0 when every demonstration arrived."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0] + " " + __doc__.split("\n\n")[1])
    add_config_arguments(parser, "demo", DemoConfig, with_zenoh=False)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, _ = resolve_config("demo", DemoConfig, args, with_zenoh=False)
        setup_logging(cfg.log_level)
        stop = threading.Event()
        restore = stop_on_signals(stop)
        try:
            return run_demo(cfg, stop, out=lambda line: print(line, flush=True))
        finally:
            restore()


if __name__ == "__main__":
    sys.exit(main())
