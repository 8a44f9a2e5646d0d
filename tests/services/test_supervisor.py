"""foresight demo's supervisor: a dead service is reported once and the run carries on, or it is restarted."""

from __future__ import annotations

from services.supervisor import Supervisor, describe_exit
from shared.stopping import SHUTDOWN_GRACE_S


class FakeProcess:
    """What the supervisor uses of a ServiceProcess."""

    def __init__(self, code: int | None = None) -> None:
        self.code = code
        self.proc = object()
        self.started = 0

    @property
    def running(self) -> bool:
        return self.code is None

    @property
    def returncode(self) -> int | None:
        return self.code

    def tail(self, lines: int = 3) -> str:
        return "last words"

    def last_words(self) -> str:
        return self.tail(1) if self.code is not None and self.code > 0 else ""

    def start(self) -> FakeProcess:
        self.started += 1
        self.code = None
        return self

    def stop(self, timeout: float = 5.0) -> int | None:
        self.stopped = getattr(self, "stopped", 0) + 1
        self.code = -9 if self.code is None else self.code
        return self.code


def test_a_killed_service_is_reported_once_and_the_run_goes_on():
    lines: list[str] = []
    procs = {"predictor": FakeProcess(), "planner": FakeProcess(), "replayer": FakeProcess(), "executor": FakeProcess()}
    sup = Supervisor(procs, lines.append)
    sup.check()
    assert lines == []
    procs["predictor"].code = -9
    procs["replayer"].code = 0  # the human's stream ended: normal
    for _ in range(3):
        sup.check()
    # a killed process's last log line is not why it died (it read as if that line had killed it)
    assert lines == ["foresight demo: predictor was killed (SIGKILL); carrying on without it (the executor holds "
                     "while its outputs are missing)"]
    assert sup.faults == [("predictor", -9)]


def test_restart_brings_a_dead_service_back_a_bounded_number_of_times():
    lines: list[str] = []
    procs = {"planner": FakeProcess(), "executor": FakeProcess()}
    sup = Supervisor(procs, lines.append, restart=True, max_restarts=2)
    for _ in range(4):
        procs["planner"].code = 1
        sup.check()
    assert procs["planner"].started == 2
    assert "restarting it (1 of 2)" in lines[0] and "restarting it (2 of 2)" in lines[1]
    assert "carrying on without it" in lines[2] and len(lines) == 3
    assert describe_exit(-15) == "was killed (SIGTERM)" and describe_exit(2) == "exited with status 2"


def test_in_lock_step_a_dead_service_ends_the_run_unless_it_is_restarted():
    """Every tick waits for every service: without the planner the run crawled on, one 30 s timeout a tick."""
    lines: list[str] = []
    procs = {"planner": FakeProcess(), "replayer": FakeProcess(), "executor": FakeProcess()}
    sup = Supervisor(procs, lines.append, fatal=True)
    procs["replayer"].code = 0  # its stream ended: the run goes on
    sup.check()
    assert sup.fatal_fault is None and lines == []
    procs["planner"].code = -9
    sup.check()
    assert sup.fatal_fault == "planner" and "cannot go on without it" in lines[0] and "--restart" in lines[0]
    restarting = Supervisor({"planner": FakeProcess(-9), "executor": FakeProcess()}, lines.append, restart=True,
                            fatal=True)
    restarting.check()
    assert restarting.fatal_fault is None  # started again instead


class Tokens:
    """Liveliness tokens and a clock the test moves."""

    def __init__(self, *alive: str) -> None:
        self.alive = set(alive)
        self.now = 0.0

    def is_alive(self, name: str) -> bool:
        return name in self.alive


def watched(service: str, **options) -> tuple[list[str], Tokens, dict[str, FakeProcess], Supervisor]:
    """``service`` and the executor under a supervisor that sees tokens; its lines, the tokens, the processes."""
    lines: list[str] = []
    tokens = Tokens(service)
    procs = {service: FakeProcess(), "executor": FakeProcess()}
    return lines, tokens, procs, Supervisor(procs, lines.append, is_alive=tokens.is_alive, clock=lambda: tokens.now,
                                            **options)


def test_a_service_whose_token_stays_gone_while_it_runs_is_hung_and_a_lock_step_run_stops():
    """A SIGSTOPped planner was never noticed: a lock-step run crept on at 30 s a tick until its --timeout."""
    lines: list[str] = []
    tokens = Tokens("planner", "predictor")
    procs = {"planner": FakeProcess(), "predictor": FakeProcess(), "replayer": FakeProcess(),
             "executor": FakeProcess()}
    sup = Supervisor(procs, lines.append, fatal=True, is_alive=tokens.is_alive, clock=lambda: tokens.now)
    sup.check()  # the replayer's token not seen yet: starting, no fault
    tokens.alive.discard("planner")
    tokens.now = 1.0
    sup.check()
    tokens.now = 9.0
    sup.check()
    assert lines == [] and sup.fatal_fault is None  # gone 8 s: a link that dropped may still come back
    tokens.now = 12.0
    sup.check()
    assert sup.fatal_fault == "planner" and sup.faults == [("planner", None)]
    assert lines == ["foresight demo: planner stopped answering (its process runs, but its liveliness token has been "
                     "gone for 11 s: hung or stopped); a lock-step run cannot go on without it (every tick waits "
                     "for it): stopping the run (--restart starts it again)"]


def test_a_token_back_within_a_links_reconnection_is_no_fault():
    """A link that drops takes 1-4 s to reconnect and its tokens are gone meanwhile: a healthy planner was killed and
    restarted after 2 s (a review's proxy that dropped the link for 3 s)."""
    lines, tokens, procs, sup = watched("planner", restart=True)
    sup.check()
    tokens.alive.clear()
    for tokens.now in (1.0, 2.5, 4.0):
        sup.check()
    tokens.alive.add("planner")
    tokens.now = 5.0
    sup.check()
    assert lines == [] and sup.faults == [] and procs["planner"].started == 0


def test_a_hung_service_is_killed_and_started_again_with_restart_and_not_judged_until_it_is_up():
    lines, tokens, procs, sup = watched("predictor", restart=True)
    sup.check()
    tokens.alive.clear()
    sup.check()
    tokens.now = 15.0
    sup.check()
    assert procs["predictor"].stopped == 1 and procs["predictor"].started == 1 and "restarting it (1 of 3)" in lines[0]
    tokens.now = 60.0  # started again, its token not up yet: starting, not hung
    sup.check()
    assert len(lines) == 1 and procs["predictor"].started == 1


def test_a_hung_executor_is_named_and_ends_the_run_even_in_real_time_and_with_restart():
    """A SIGSTOPped executor was never looked at (the supervisor skipped it): with the default --timeout a run sat
    silent for 15 minutes (a review)."""
    for options in ({}, {"restart": True}, {"fatal": True}):
        lines, tokens, procs, sup = watched("planner", **options)
        tokens.alive.add("executor")
        sup.check()
        tokens.alive.discard("executor")
        sup.check()
        tokens.now = 11.0  # gone as long as a hung planner, but it may be closing its log (a full disk's retries)
        sup.check()
        assert sup.fatal_fault is None and lines == [], options
        tokens.now = 11.0 + SHUTDOWN_GRACE_S
        sup.check()
        sup.check()  # said once
        assert sup.fatal_fault == "executor" and sup.faults == [("executor", None)], options
        assert lines == ["foresight demo: executor stopped answering (its process runs, but its liveliness token has "
                         "been gone for 21 s: hung or stopped); the run cannot go on without it: stopping the run"]
        assert procs["executor"].started == 0  # not restarted: it holds the run's clock and its log
