"""How a demo run ends (services.demo_run.run_once with fake services): its exit status, its closing words, its stop."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from types import SimpleNamespace

from services import demo_run
from services.demo import STOP_GRACE_S, DemoConfig


class _Service(demo_run.ServiceProcess):
    """A service that "runs" at once; the executor ends after a few looks with ``ends[name]``, the others live unless
    ``dead`` names them (status -9). Its stops are recorded; a stubborn one takes all it is given (:data:`CLOCK`)."""

    ends: dict[str, int] = {}
    dead: set[str] = set()
    log_lines: dict[str, str] = {}
    stops: list[tuple[str, float, float]] = []
    stubborn = False

    def start(self) -> _Service:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self.log_path.write_text(self.log_lines.get(self.name, ""))
        self._log_from, self.looks, self.code = 0, 0, None
        self.proc = object()  # started, as the supervisor sees it
        if self.name in self.dead and not getattr(self, "started_once", False):
            self.code = -9  # killed mid-run: a restart brings it back
        self.started_once = True
        return self

    @property
    def running(self) -> bool:
        if self.name == "executor" and self.code is None:
            self.looks += 1
            if self.looks > 5:
                self.code = self.ends.get("executor", 0)
        return self.code is None

    @property
    def returncode(self) -> int | None:
        return self.code

    def wait_alive(self, is_alive, timeout, stop=None) -> bool:
        return True

    def stop(self, timeout: float = 5.0, kill_wait: float = 5.0) -> int | None:
        self.stops.append((self.name, timeout, kill_wait))
        if self.stubborn and self.code is None:  # ignores SIGTERM, ends only after its SIGKILL's wait
            CLOCK[0] += timeout + kill_wait
        self.code = -15 if self.code is None else self.code
        return self.code


CLOCK = [0.0]
"""Seconds the fake stops have taken, added to the real monotonic clock."""


class _Recorder:
    """Three plans received."""

    def on_message(self, msg: object) -> None:
        pass

    def snapshot(self) -> tuple[list[object], list[object], None, dict[int, object]]:
        return [object()] * 3, [], None, {}

    def plan_arrivals(self) -> list[float]:
        return [0.0, 0.1, 0.2]

    def human_poses(self) -> list[object]:
        return []


def _run(monkeypatch, tmp_path: Path, **options) -> tuple[int, object, list[str]]:
    """One run of fake services under ``DemoConfig(**options)``; its status, record and lines."""
    scenario = SimpleNamespace(demo=SimpleNamespace(class_name="blue_cup"), samples_per_tick=1)
    monkeypatch.setattr(demo_run, "prepare_inputs", lambda *a: (scenario, tmp_path / "m.npz", tmp_path / "h.npz"))
    monkeypatch.setattr(demo_run, "ServiceProcess", _Service)
    monkeypatch.setattr(demo_run, "RunRecorder", _Recorder)
    monkeypatch.setattr(demo_run, "summarise", lambda *a, **k: SimpleNamespace(steps=[1, 2, 3], extra={}))
    said: list[str] = []
    status, record = demo_run.run_once(DemoConfig(run_dir=str(tmp_path), **options), "prediction", threading.Event(),
                                       said.append)
    return status, record, said


def _fakes(monkeypatch, **attrs) -> None:
    for name, value in {"ends": {}, "dead": set(), "log_lines": {}, "stops": [], "stubborn": False, **attrs}.items():
        monkeypatch.setattr(_Service, name, value)


def test_a_run_whose_log_is_incomplete_exits_4_and_is_not_called_stopped(monkeypatch, tmp_path: Path) -> None:
    """A full disk: the executor said its log INCOMPLETE (status 4) and `foresight demo` exited 0 (a review)."""
    line = "mcap: x.mcap: INCOMPLETE: 5 of 9 messages written (No space left on device: 99 bytes refused for 3 s)"
    _fakes(monkeypatch, ends={"executor": 4}, log_lines={"executor": line + "\n"})
    status, record, said = _run(monkeypatch, tmp_path)
    assert status == 4 and record is not None, said
    assert record.summary.extra["log_incomplete"] == line.removeprefix("mcap: ")  # the closing MCAP line's
    assert not [ln for ln in said if "stopped after" in ln or "executor exited" in ln or "not whole" in ln], said


def test_a_real_time_run_that_lost_a_service_exits_1(monkeypatch, tmp_path: Path) -> None:
    """A planner killed in real time: "carrying on without it", "faults during the run", and status 0 (a review)."""
    _fakes(monkeypatch, dead={"planner"})
    status, record, said = _run(monkeypatch, tmp_path, mode="realtime")
    assert status == 1 and record is not None, said
    assert "foresight demo: faults during the run: planner (killed)" in said
    assert record.summary.extra["cut_short"] == "faults during the run: planner (killed)"
    assert said[-1] == ("foresight demo: the run went to its end, but it is not whole (3 plans; see above): exit "
                        "status 1")


def test_ticks_without_their_plan_are_said_so_not_with_the_executors_last_line(monkeypatch, tmp_path: Path) -> None:
    """Lock-step with --restart, the planner killed: "executor exited with status 1: mcap: runs4/...mcap" (its last
    line, not a reason) and "stopped after 19 of 20 steps" though every tick ran (a review)."""
    _fakes(monkeypatch, ends={"executor": 1}, dead={"planner"}, log_lines={"executor": "mcap: runs4/x.mcap\n"})
    status, record, said = _run(monkeypatch, tmp_path, restart=True)
    assert status == 1 and record is not None, said
    assert not [ln for ln in said if "mcap: runs4" in ln or "stopped after" in ln], said
    (went,) = [ln for ln in said if "some of its ticks went on without their plan or prediction" in ln]
    assert str(tmp_path / "executor.log") in went
    assert said[-1] == ("foresight demo: the run went to its end, but it is not whole (3 plans for its 20 steps; see "
                        "above): exit status 1")


def test_stubborn_services_stop_within_the_demos_grace(monkeypatch, tmp_path: Path) -> None:
    """Each service had 12 s and 5 s after its kill: the five stubborn ones after the executor (--ros2 --robot
    ros2-sim) took 85 s, 6-7 took past the 90 s a signal gives the demo, whose forced exit (status 3) cut its orderly
    stop short (a review)."""
    _fakes(monkeypatch, stubborn=True)
    real = time.monotonic
    CLOCK[0] = 0.0
    monkeypatch.setattr(time, "monotonic", lambda: real() + CLOCK[0])
    status, record, said = _run(monkeypatch, tmp_path, ros2=True, robot="ros2-sim")
    assert status == 0 and len(_Service.stops) == 6, (said, _Service.stops)
    assert _Service.stops[0][:2] == ("executor", 12.0)  # first, with its whole grace: it closes the log
    assert CLOCK[0] <= STOP_GRACE_S - 20, _Service.stops  # room left for the summary and the picture


def test_one_budget_bounds_the_stop_of_seven_stubborn_services() -> None:
    """Seven services that each take all they are given: the first (the executor) its whole grace, the rest what is
    left of the budget, a second or two each once it is spent."""
    from services.demo_status import STOP_BUDGET_S, stop_in_order

    now = [0.0]

    class Stubborn:
        running = True

        def stop(self, timeout: float, kill_wait: float) -> int:
            now[0] += timeout + kill_wait
            return -9

        def tail(self, lines: int = 1) -> str:
            return "said something"

    names = [f"s{i}" for i in range(7)]
    stopped = list(stop_in_order({n: Stubborn() for n in names}, names, 12.0, clock=lambda: now[0]))
    assert stopped == [(n, -9) for n in names]
    assert STOP_BUDGET_S <= now[0] <= STOP_BUDGET_S + 7 * 1.5 <= STOP_GRACE_S - 15, now
