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


class _Clock:
    """time.monotonic / time.sleep of tools.faults on a clock the test moves (a kill at 10 s)."""

    def __init__(self, monkeypatch) -> None:
        self.now = 10.0
        monkeypatch.setattr(faults.time, "monotonic", lambda: self.now)
        monkeypatch.setattr(faults.time, "sleep", self.sleep)

    def sleep(self, s: float) -> None:
        self.now += s


class _Recorded(_Watcher):
    def __init__(self, states: list, tokens: list) -> None:
        super().__init__(moves=True)
        self.states, self.tokens, self.plans, self.occupancy = states, tokens, [], []

    def snapshot(self, items):
        return list(items)


def _moving(t: float) -> tuple[float, NS]:
    return (t, NS(holding=False, reason=""))


def _holding(t: float) -> tuple[float, NS]:
    return (t, NS(holding=True, reason="predictor gone"))


@pytest.mark.parametrize("states, moved", [
    ([_moving(10.5), _moving(11.0), _moving(12.0), _moving(14.0)], 3),  # never held: it read 0
    ([_moving(10.5), _holding(13.2), _moving(14.0)], 1),  # held only after the restart (13 s): it read 0
    ([_holding(10.2), _moving(11.0), _holding(12.0), _moving(14.0)], 1),  # held, then moved once while down
])
def test_a_robot_that_moved_while_the_victim_was_down_counts_those_states(tmp_path, monkeypatch, states, moved):
    """With no hold seen, ``moved_while_down`` counted nothing: a robot that never held read "0 states"."""
    clock = _Clock(monkeypatch)
    tokens: list = []
    s = _system(tmp_path, {"predictor": _Proc(None)})
    s.kill = lambda name: None
    s.start = lambda name: tokens.append((clock.now + 0.5, name, True))
    r = faults.measure_kill(s, _Recorded(states, tokens), "predictor", down_s=3.0, timeout=1.0)
    assert r["moved_while_down"] == moved, r
    held = "never held" if r["hold_s"] is None else f"held {r['hold_s']:.2f} s after the kill"
    assert faults.moved_failures([r]) == [f"the robot moved {moved} states while the predictor was down ({held})"]
    assert faults.moved_failures([{**r, "victim": "router"}]) == []  # no hold is needed without the router


def test_the_router_is_back_when_its_port_takes_connections(tmp_path, monkeypatch):
    """It was started with start(), which does not wait: "back 0.00 s" whatever the router did."""
    clock = _Clock(monkeypatch)
    s = _system(tmp_path, {"router": _Proc(None)})
    s.kill = lambda name: None
    s.start = lambda name: None
    s.start_router = lambda timeout=30.0: clock.sleep(0.4)
    r = faults.measure_kill(s, _Recorded([_moving(10.5), _moving(13.6)], []), "router", down_s=3.0, timeout=1.0)
    assert r["back_s"] == pytest.approx(0.4) and r["moved_while_down"] == 1, r
    assert ("back", pytest.approx(3.4)) in r["events"]


def test_faults_reads_back_every_mcap_and_fails_when_the_robot_moved(tmp_path, monkeypatch, capsys):
    """Only the newest run-<n>.mcap was read back (the one the executor was killed in never was), and a robot that
    moved while a service was down exited 0."""
    read: list[str] = []

    class System:
        def __init__(self, spec):
            self.spec, self.endpoint = spec, "tcp/127.0.0.1:1"
            self.starts = {"executor": 2}  # killed as a victim once: run.mcap, then run-1.mcap
            self.mcap_path = spec.run_dir / "run-1.mcap"

        def start_router(self):
            pass

        def start_services(self):
            pass

        def kill(self, name):
            pass

        def close(self):
            return {}

    class Watcher:
        def __init__(self, *a, **k):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    kill = {"victim": "executor", "hold_s": None, "hold_reason": "", "moved_while_down": 4, "back_s": 0.5,
            "resume_s": 0.1, "resume_after_start_s": 0.6, "resume_after_output_s": None, "events": []}
    monkeypatch.setattr(faults, "ProcessSystem", System)
    monkeypatch.setattr(faults, "Watcher", Watcher)
    monkeypatch.setattr(faults, "demo_model", lambda models_dir: tmp_path / "m.npz")
    monkeypatch.setattr(faults, "measure_kill", lambda *a: kill)
    monkeypatch.setattr(faults, "stale_releases", lambda *a: [])
    monkeypatch.setattr(faults, "read_log", lambda path: read.append(Path(path).name) or NS(
        size=1000, complete=False, error="", message_count=3, channels={}))
    code = faults.main(["--victims", "executor", "--run-dir", str(tmp_path)])
    out, err = capsys.readouterr()
    assert read == ["run.mcap", "run-1.mcap"] and out.count("executor SIGKILLed: ") == 2, out
    assert code == 1 and err.strip() == ("foresight bench faults: the robot moved 4 states while the executor was "
                                         "down (never held)")


def test_the_demo_model_says_it_trains_before_the_minute_it_takes(tmp_path, monkeypatch, capsys):
    """faults and soak were silent for about a minute on first use."""
    import services.scenario
    import shared.synthetic

    def model_for(lib, scene, demo, models_dir, on_train=None, **kwargs):
        if on_train is not None:
            on_train(models_dir / "m.npz")
        return models_dir / "m.npz"

    monkeypatch.setattr(shared.synthetic, "generate_library", lambda **k: None)
    monkeypatch.setattr(services.scenario, "choose_demonstration", lambda *a: NS(demo=None))
    monkeypatch.setattr(services.scenario, "model_for", model_for)
    assert faults.demo_model(tmp_path) == tmp_path / "m.npz"
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "training the prediction model once, about a minute" in err
    assert str(tmp_path / "m.npz") in err
