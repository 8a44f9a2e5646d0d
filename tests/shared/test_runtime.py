"""shared.runtime: the start-up heap is frozen out of the garbage collector before a service serves."""

from __future__ import annotations

import gc
import io
import signal
import subprocess
import sys
import types
import weakref
from pathlib import Path

import pytest

from shared.runtime import cli_errors, freeze_startup_heap, setup_logging
from tools import foresight

REPO = Path(__file__).resolve().parents[2]


class _Node:
    def __init__(self) -> None:
        self.other: _Node | None = None


def test_freeze_startup_heap_collects_garbage_then_freezes_the_rest() -> None:
    enabled = gc.isenabled()
    gc.disable()  # no automatic collection in between: only freeze_startup_heap may free the cycle
    try:
        a, b = _Node(), _Node()
        a.other, b.other = b, a  # a reference cycle: only the collector frees it
        cycle = weakref.ref(a)
        del a, b
        kept = [_Node() for _ in range(100)]
        assert cycle() is not None
        frozen = freeze_startup_heap()
        assert cycle() is None  # collected before the freeze, not frozen as garbage
        # the count at the freeze: another thread of this process (pytest-xdist's I/O thread, say) may free a
        # frozen object before the next line reads the count again, so that one may be a little lower
        assert frozen >= len(kept) and 0 < gc.get_freeze_count() <= frozen
        assert not any(o is kept[0] for o in gc.get_objects())  # out of every generation (identity only:
        # probing the other objects' classes would trip lazy module attributes that warn)
    finally:
        gc.unfreeze()
        if enabled:
            gc.enable()
    assert any(o is kept[0] for o in gc.get_objects())  # tracked again


def test_watch_parent_stops_at_once_when_the_parent_died_during_start_up(monkeypatch) -> None:
    """A service still importing when the demo died used to find 'nothing to watch' and run on, orphaned."""
    import os
    import subprocess
    import sys
    import threading

    from shared.runtime import PARENT_ENV, watch_parent

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          timeout=30, check=True)
    monkeypatch.setenv(PARENT_ENV, gone.stdout.strip())  # a pid that has exited: the parent is gone
    stop = threading.Event()
    assert watch_parent(stop) == int(gone.stdout) and stop.is_set()
    monkeypatch.setenv(PARENT_ENV, str(os.getpid()))  # alive, but not the parent: inherited by a grandchild
    stop = threading.Event()
    assert watch_parent(stop) is None and not stop.is_set()
    monkeypatch.setenv(PARENT_ENV, str(os.getppid()))  # the parent, alive: watched on a thread
    stop = threading.Event()
    assert watch_parent(stop, period_s=0.05) == os.getppid() and not stop.wait(0.2)
    stop.set()  # ends the watching thread


def test_a_log_level_that_is_no_level_is_refused_rather_than_read_as_info() -> None:
    with pytest.raises(ValueError, match="log level 'DEBGU': not one of DEBUG, INFO, WARNING, ERROR"):
        setup_logging("DEBGU")



def test_a_broken_pipe_passes_through_to_the_dispatcher(monkeypatch):
    """Output piped into `head` ended a command as 'error: Broken pipe', status 2: cli_errors took it for a disk
    error; the dispatcher, which returns 0 for it, never saw it."""
    with pytest.raises(BrokenPipeError), cli_errors("foresight x"):
        raise BrokenPipeError(32, "Broken pipe")

    def closed_pipe(argv: list[str], prog: str) -> int:
        with cli_errors(prog):
            raise BrokenPipeError(32, "Broken pipe")

    command = types.ModuleType("fake_command")
    command.main = closed_pipe
    monkeypatch.setitem(sys.modules, "fake_command", command)
    monkeypatch.setitem(foresight.COMMANDS, "fake", ("fake_command", "a command whose reader went away"))
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # the dispatcher closes it (nothing more can be said)
    assert foresight.main(["fake"]) == 0


def test_help_text_shows_cross_references_as_the_names_they_refer_to() -> None:
    """`foresight eval all --help` printed ':mod:`services.experiments.protocol`'."""
    from shared.runtime import help_text

    assert help_text("see :mod:`services.x` and :func:`~a.b.c`, ``--flag``") == "see `services.x` and `a.b.c`, `--flag`"


def test_a_service_with_a_refused_certificate_ends_before_it_is_built(tmp_path, capsys) -> None:
    """The planner loaded torch and compiled its cost (3-4 s) before its expired certificate ended it."""
    import dataclasses
    import datetime as dt

    from shared.runtime import service_main
    from shared.security.certificates import Issued, init_security_dir, issue

    cell = tmp_path / "cell"
    init_security_dir(cell, ["planner"])
    old = issue(Issued((cell / "ca.crt").read_bytes(), (cell / "ca.key").read_bytes()), "planner",
                not_after=dt.datetime.now(dt.UTC) - dt.timedelta(hours=1))
    (cell / "planner.crt").write_bytes(old.cert_pem)
    (cell / "planner.key").write_bytes(old.key_pem)

    @dataclasses.dataclass
    class Config:
        log_level: str = "INFO"

    built = []
    with pytest.raises(SystemExit) as exit_:
        service_main(["--zenoh-mode", "client", "--connect", "tls/127.0.0.1:9", "--listen", "", "--security",
                      str(cell)], "foresight planner", section="planner", config_cls=Config, description="",
                     make=lambda *a: built.append(a))
    assert exit_.value.code == 2 and built == []
    assert "planner.crt: expired at" in capsys.readouterr().err


def test_a_command_that_is_no_role_refuses_security_itself(tmp_path, capsys) -> None:
    """foresight ros2 / simrobot under --security: the early certificate check asked for an observer certificate
    instead of letting them say that ROS 2 keys have no role in the access control."""
    from services.ros2.__main__ import main
    from shared.security.certificates import init_security_dir

    cell = tmp_path / "cell"
    init_security_dir(cell, ["router", "planner"])
    with pytest.raises(SystemExit) as exit_:
        main(["--zenoh-mode", "client", "--connect", "tls/127.0.0.1:9", "--listen", "", "--security", str(cell)])
    assert exit_.value.code == 2
    assert "ROS 2 keys have no role in the access control" in capsys.readouterr().err


BUILDING = """
import dataclasses, sys, time
from shared.runtime import service_main

@dataclasses.dataclass
class Config:
    log_level: str = "INFO"

def make(cfg, zcfg, stop):
    print("building", flush=True)
    time.sleep(600)  # a build that checks no stop event (the planner compiling its kernels)
    return lambda: print("served", flush=True)

sys.exit(service_main(["--listen", "tcp/127.0.0.1:0"], "foresight planner", section="planner", config_cls=Config,
                      description="", make=make))
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_while_the_service_is_built_ends_it_at_once_with_status_0(sig, signalled) -> None:
    """A planner stopped while it compiled its kernels (docker compose down, Ctrl-C at start-up) ran on for the grace,
    then exited with status 3 and ~80 lines of every thread's stack."""
    end = signalled(["-c", BUILDING], [(sig, 0.0)], ready="building", timeout=30)
    assert end.returncode == 0, end.stderr
    assert "foresight planner: stopped while starting" in end.stderr
    assert "Traceback" not in end.stderr and "stacks" not in end.stderr
    assert "served" not in end.stdout


SIGNAL_ANOTHER_THREAD = """
import signal, threading, time

def signal_another_thread(sig, after_s=0.5):
    # a thread that takes sig itself once the main thread is asleep: the kernel's choice, made every time
    threading.Thread(target=lambda: (time.sleep(after_s), signal.pthread_kill(threading.get_ident(), sig)),
                     daemon=True).start()
"""


def _build(body: str) -> str:
    """:data:`BUILDING` with the grace at 1 s, ``signal_another_thread`` defined, and ``body`` as ``make``'s."""
    head, tail = BUILDING.split("def make(cfg, zcfg, stop):\n")
    tail = tail[tail.index("\nsys.exit"):]
    return (head.replace("from shared.runtime import service_main",
                         "from shared import runtime, stopping\n"
                         "runtime.SHUTDOWN_GRACE_S = stopping.SHUTDOWN_GRACE_S = 1.0\n"
                         "from shared.runtime import service_main")
            + SIGNAL_ANOTHER_THREAD + "def make(cfg, zcfg, stop):\n" + body + tail)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_another_thread_received_while_the_service_is_built_ends_it_at_once(sig, signalled) -> None:
    """The kernel hands a process's signal to any of its threads: when it chose another (OpenBLAS's) while the main
    thread slept in the build, the handler waited for the sleep to end. A CI run: Ctrl-C at start-up did not end
    the service in 30 s (the test above, which signals the process, not one of its threads)."""
    code = _build(f"    signal_another_thread({int(sig)})\n"
                  '    print("building", flush=True)\n'
                  "    time.sleep(600)\n"
                  '    return lambda: print("served", flush=True)\n')
    end = signalled(["-c", code], [], ready="building", timeout=30)
    assert end.returncode == 0, end.stderr[-2000:]
    assert "foresight planner: stopped while starting" in end.stderr
    assert "Traceback" not in end.stderr and "served" not in end.stdout


def test_a_service_stuck_in_a_call_exits_after_the_grace_when_another_thread_got_the_signal(signalled) -> None:
    """The shutdown watchdog was started by the handler, in the main thread: with the signal on another thread
    and the main thread stuck in a call, it never started, and the service hung until killed."""
    code = _build("    def run():\n"
                  "        signal_another_thread(signal.SIGTERM)\n"
                  '        print("serving", flush=True)\n'
                  "        time.sleep(600)  # a call that does not look at the stop event\n"
                  "    return run\n")
    end = signalled(["-c", code], [], ready="serving", timeout=30)
    assert end.returncode == 3, end.stderr[-2000:]
    assert "foresight planner: did not stop within 1 s of SIGTERM" in end.stderr, end.stderr[-2000:]


NATIVE_BUILD = ("    import hashlib\n"
                '    print("building", flush=True)\n'
                "    for _ in range(400):  # native calls of ~0.25 s each: Python's handler runs only between them\n"
                "        hashlib.pbkdf2_hmac('sha256', b'x', b'y', 300_000)\n"
                '    return lambda: print("served", flush=True)\n')


def test_a_build_in_native_calls_is_ended_after_the_grace_and_a_second_signal_ends_it_at_once(signalled) -> None:
    """While a service was built, the build's own handler replaced the shutdown watchdog: a build in a long native
    call ignored a second SIGTERM and ended only when the call did (a review: 13 s, status 0)."""
    once = signalled(["-c", _build(NATIVE_BUILD)], [(signal.SIGTERM, 0.0)], ready="building", timeout=60)
    assert once.returncode in (0, 3), once.stderr[-2000:]  # cut between two calls, or by the watchdog after 1 s
    assert "served" not in once.stdout
    twice = signalled(["-c", _build(NATIVE_BUILD.replace("300_000", "30_000_000"))],
                      [(signal.SIGTERM, 0.0), (signal.SIGTERM, 0.5)], ready="building", timeout=60)
    assert twice.returncode == 3, twice.stderr[-2000:]  # one native call of ~25 s: the second signal ends it
    assert "foresight planner: second SIGTERM while starting; exiting with status 3" in twice.stderr, twice.stderr


def test_a_thread_left_running_after_the_service_stopped_does_not_hold_the_exit(signalled) -> None:
    """After a signal, run() returned but a non-daemon thread it had started kept the process alive (a review: 25 s):
    the shutdown watchdog had ended with the run."""
    code = _build("    def run():\n"
                  "        threading.Thread(target=time.sleep, args=(600,)).start()  # a worker, not a daemon\n"
                  '        print("serving", flush=True)\n'
                  "        runtime.wait_for_stop(stop)\n"
                  "    return run\n").replace("import signal, threading, time", "import signal, threading, time\n"
                                             "from shared import runtime", 1)
    end = signalled(["-c", code], [(signal.SIGTERM, 0.0)], ready="serving", timeout=30)
    assert end.returncode == 3, end.stderr[-2000:]
    assert "foresight planner: did not exit within 1 s of its stop" in end.stderr, end.stderr[-2000:]


def test_debug_is_foresights_own_and_other_libraries_stay_at_info() -> None:
    """`--log-level DEBUG` set the root logger: 292 of a demo's 294 DEBUG lines were matplotlib's font search, and a
    planner's per-plan lines came with filelock's every lock."""
    code = ("import logging; from shared.runtime import setup_logging; setup_logging('DEBUG'); "
            "logging.getLogger('foresight.planner').debug('ours'); logging.getLogger('services.x').debug('module'); "
            "logging.getLogger('matplotlib.font_manager').debug('theirs'); logging.getLogger('filelock').info('info')")
    err = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60).stderr
    assert "ours" in err and "module" in err and "info" in err and "theirs" not in err, err


BUILDING_WITH_A_WORKER = BUILDING.replace(
    '    print("building", flush=True)',
    '    import threading\n    threading.Thread(target=time.sleep, args=(600,)).start()  # a worker, not a daemon\n'
    '    print("building", flush=True)  # after the worker started: the signal comes once it runs')


def test_a_worker_left_by_a_stopped_build_does_not_hold_the_exit_past_the_grace(signalled) -> None:
    """A build stopped by a signal returned 0, but a non-daemon thread it had started kept the interpreter waiting as
    long as it ran (a review's script: 25 s), where the shutdown watchdog used to force the exit after the grace."""
    code = BUILDING_WITH_A_WORKER.replace("from shared.runtime import service_main",
                                          "from shared import runtime, stopping\n"
                                          "runtime.SHUTDOWN_GRACE_S = stopping.SHUTDOWN_GRACE_S = 1.0\n"
                                          "from shared.runtime import service_main")
    end = signalled(["-c", code], [(signal.SIGTERM, 0.0)], ready="building")
    assert end.returncode == 3, end.stderr[-2000:]
    assert "did not exit within 1 s of stopping while starting" in end.stderr, end.stderr[-2000:]


WAITING = """
import signal, sys, threading
from shared import runtime
stop = threading.Event()
threading.Thread(target=threading.Event().wait, daemon=True).start()  # a thread the kernel may hand a signal to
runtime.stop_on_signals(stop, grace_s=30.0, prog="waiting")
signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGTERM])  # so the kernel does: the main thread's wait is not cut
print("ready", flush=True)
runtime.wait_for_stop(stop) if sys.argv[1] == "wait_for_stop" else stop.wait()
print("stopped", flush=True)
"""


@pytest.mark.parametrize("wait", ["wait_for_stop", "plain"])
def test_a_signal_another_thread_received_still_ends_the_wait_for_stop(wait, signalled) -> None:
    """The handler of a signal delivered to another thread (or just before the wait's syscall) runs only when the
    main thread next runs bytecode: a plain ``stop.wait()`` never ended, :func:`wait_for_stop` within its poll.
    Now the relay (:mod:`shared.signal_relay`) sets ``stop`` from a thread of its own: both end at once."""
    end = signalled(["-c", WAITING, wait], [(signal.SIGTERM, 0.0)], timeout=20)
    assert (end.returncode, end.stdout.strip()) == (0, "stopped"), end.stderr


HELD = """
import dataclasses, os, signal, sys, time
from shared.runtime import PARENT_ENV, service_main

@dataclasses.dataclass
class Config:
    log_level: str = "INFO"

def make(cfg, zcfg, stop):
    def run():
        print("serving", flush=True)
        time.sleep(0.5)  # past a first signal's echo: had the held Ctrl-C been obeyed, this were a second signal
        os.kill(os.getpid(), signal.SIGTERM)  # the parent stopping its services
        print("stopped" if stop.wait(30) else "running", flush=True)
    return run

signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGINT])  # as services.processes.ServiceProcess forks it
os.kill(os.getpid(), signal.SIGINT)  # a Ctrl-C to the parent's group as it was forked: held
if sys.argv[1] == "parent":
    os.environ[PARENT_ENV] = str(os.getppid())
else:
    os.environ.pop(PARENT_ENV, None)
print("ready", flush=True)
sys.exit(service_main(["--listen", "tcp/127.0.0.1:0"], "foresight replayer", section="replayer", config_cls=Config,
                      description="", make=make))
"""


def test_a_ctrl_c_held_since_a_parent_forked_the_service_is_the_parents_and_dropped(signalled) -> None:
    """The parent (``foresight demo``) got the same Ctrl-C and stops its services itself, in its own order, with
    SIGTERM; the held one was obeyed as the handlers were installed: the service stopped while starting."""
    end = signalled(["-c", HELD, "parent"], [], timeout=30)
    assert (end.returncode, end.stdout.split()) == (0, ["serving", "stopped"]), end.stderr[-2000:]
    assert "stopped while starting" not in end.stderr, end.stderr[-2000:]
    # without a Foresight parent, a Ctrl-C held since start (a parent of another kind blocked it) is this one's
    end = signalled(["-c", HELD, "none"], [], timeout=30)
    assert end.returncode == 0 and "serving" not in end.stdout, end.stderr[-2000:]
    assert "foresight replayer: stopped while starting" in end.stderr, end.stderr[-2000:]


STOPPING = """
import sys, threading, time
from shared import runtime
stop = threading.Event()
context = (lambda: "this run's files: /runs/x/") if sys.argv[1] == "context" else None
runtime.stop_on_signals(stop, grace_s=30.0, prog="stopping", **({"context": context} if context else {}))
print("ready", flush=True)
stop.wait(30)
time.sleep(30)  # an orderly stop that takes its time (the demo's services stopping, one after the other)
"""


@pytest.mark.parametrize("context", ["context", "none"])
def test_a_forced_exit_ends_its_one_line_with_the_context_it_was_given(context, signalled) -> None:
    """``foresight demo``'s second Ctrl-C while it stopped said only "second SIGINT while stopping; exiting with status
    3": not where the run's files were, nor that its services stop on their own (a new user's first hour). Other
    processes give no context, and their line is as it was."""
    end = signalled(["-c", STOPPING, context], [(signal.SIGTERM, 0.0), (signal.SIGTERM, 0.5)], timeout=20)
    assert end.returncode == 3, end.stderr[-2000:]
    line = "stopping: second SIGTERM while stopping; exiting with status 3"
    assert end.stderr == (f"{line}; this run's files: /runs/x/\n" if context == "context" else f"{line}\n")
