"""``foresight bench faults`` / ``soak`` and their process system: options checked before anything starts,
a run that never moves ends in one line naming what exited, a victim that never comes back reads "-"."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace as NS

import pytest

import tools.faults as faults
import tools.soak as soak
import tools.system as system_mod
from shared.runtime import UserError
from tools.system import ProcessSystem, SystemSpec


@pytest.fixture
def nothing_starts(monkeypatch):
    """Any attempt to build the model or start the system fails the test."""
    def refuse(*a, **k):
        raise AssertionError("started although an option was bad")
    monkeypatch.setattr(faults, "demo_model", refuse)
    monkeypatch.setattr(soak, "demo_model", refuse)


@pytest.mark.parametrize("main, argv, message", [
    (faults.main, ["--victims", "planer"], "unknown 'planer' (choose from router, predictor"),
    (faults.main, ["--victims", ","], "--victims ',': empty"),
    (faults.main, ["--timeout", "nan"], "--timeout: 'nan': must be a finite number > 0"),
    (faults.main, ["--down-s", "-1"], "--down-s: '-1': must be a finite number >= 0"),
    (soak.main, ["--duration-s", "-1"], "--duration-s: '-1': must be a finite number > 0"),
    (soak.main, ["--duration-s", "inf"], "must be a finite number"),
    (soak.main, ["--rate-hz", "0"], "--rate-hz: '0': must be a finite number >= 0.01 and <= 10000"),
    (soak.main, ["--timeout", "abc"], "'abc' is not a number"),
])
def test_bad_options_are_refused_before_anything_starts(nothing_starts, capsys, main, argv, message):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


class _Proc:
    def __init__(self, code: int | None, last: str = "") -> None:
        self.returncode, self._last = code, last
        self.running = code is None

    def tail(self, lines: int = 3) -> str:
        return self._last


class _Watcher:
    def __init__(self, moves: bool) -> None:
        self._moves = moves
        self.waited = 0.0

    def moving(self) -> bool:
        return self._moves

    def wait(self, pred, timeout, poll=0.02):
        self.waited = timeout
        return pred()


def _system(tmp_path: Path, procs: dict) -> ProcessSystem:
    s = ProcessSystem.__new__(ProcessSystem)
    s.spec = SystemSpec(run_dir=tmp_path, model=tmp_path / "m.npz")
    s.procs = procs
    return s


def test_a_process_that_exited_is_named_instead_of_waiting_for_the_timeout(tmp_path):
    s = _system(tmp_path, {"router": _Proc(None), "replayer": _Proc(2, "replayer: error: rate_hz bad")})
    with pytest.raises(UserError) as exc:
        s.wait_moving(_Watcher(moves=False), 240.0, before=" (before killing planner)")
    text = str(exc.value)
    assert "replayer exited with status 2 (replayer: error: rate_hz bad)" in text
    assert "(before killing planner)" in text and str(tmp_path) in text


def test_a_robot_that_never_moves_is_one_user_error(tmp_path):
    s = _system(tmp_path, {"router": _Proc(None)})
    with pytest.raises(UserError, match=r"the robot did not move within 0.5 s; the logs are in"):
        s.wait_moving(_Watcher(moves=False), 0.5)
    s.wait_moving(_Watcher(moves=True), 0.5)  # moving, nothing exited: returns


def test_a_victim_whose_token_never_comes_back_has_no_back_time(tmp_path, monkeypatch):
    states = [(0.0, NS(holding=False, reason=""))]

    class W(_Watcher):
        tokens: list = []
        plans: list = []
        occupancy: list = []

        def __init__(self):
            super().__init__(moves=True)
            self.states = states

        def snapshot(self, items):
            return list(items)

    s = _system(tmp_path, {"planner": _Proc(None)})
    s.kill = lambda name: None
    s.start = lambda name: None
    monkeypatch.setattr(faults.time, "sleep", lambda x: None)
    r = faults.measure_kill(s, W(), "planner", down_s=0.0, timeout=0.01)
    assert r["back_s"] is None and r["resume_s"] is None
    assert "back - after restart" in faults._line(r)


def test_a_window_without_latencies_prints_dashes_not_zero():
    assert soak._ms(None) == "-" and soak._ms(0.012) == "12 ms"


def test_a_watcher_whose_subscription_fails_closes_its_session(monkeypatch):
    closed = []

    class Ctx:
        def __enter__(self):
            return object()

        def __exit__(self, *a):
            closed.append(True)

    monkeypatch.setattr(system_mod, "open_session", lambda cfg, name: Ctx())

    def fail(*a, **k):
        raise RuntimeError("declare failed")
    monkeypatch.setattr(system_mod, "subscribe", fail)
    with pytest.raises(RuntimeError, match="declare failed"):
        with system_mod.Watcher("tcp/127.0.0.1:7447"):
            pass
    assert closed == [True]


def test_an_executor_started_again_keeps_the_first_runs_log(tmp_path, monkeypatch):
    """It used to open run.mcap again, which emptied the record of the run it replaced."""
    started = []
    monkeypatch.setattr(system_mod.ServiceProcess, "start", lambda self: started.append(self.args) or self)
    s = ProcessSystem(SystemSpec(run_dir=tmp_path, model=tmp_path / "m.npz"))
    s.start("executor")
    s.start("executor")
    first, second = (a[a.index("--mcap") + 1] for a in started)
    assert first == str(tmp_path / "run.mcap") and second == str(tmp_path / "run-1.mcap")
    assert s.mcap_path == tmp_path / "run-1.mcap"
