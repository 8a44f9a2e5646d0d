"""How a demo run ends: its exit status from the executor's and the supervisor's, and its services' bounded stop.

Exit status of a run (and of ``foresight demo``): 0 a whole run; 1 a service failed (at start, dead or hung in
lock-step, the executor's own failure), a timeout, or a run that went to its end but not whole (a service dead or
restarted during a real-time run, ticks that went on without their plan); 4 its MCAP log is not complete (the
executor's :data:`~services.executor.result.LOG_INCOMPLETE`: a full disk); 130 interrupted.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING

from services.demo_dirs import stop_service
from services.executor.result import INCOMPLETE, LOG_INCOMPLETE
from services.processes import describe_exit

if TYPE_CHECKING:
    from services.processes import ServiceProcess

__all__ = ["STOP_BUDGET_S", "KILL_WAIT_S", "ending", "stop_in_order"]

STOP_BUDGET_S = 60.0
"""Seconds the stop of all a run's services may take together: inside the 90 s a signal gives the demo
(``services.demo.STOP_GRACE_S``), with room for the summary and the picture after it. Each service had 12 s and 5 s
more after its SIGKILL of its own: 6-7 stubborn ones passed 90 s, and the forced exit (status 3) cut the orderly stop
short (a review)."""

KILL_WAIT_S = 5.0
"""Seconds a service may take to end after its SIGKILL (at least 1 s once the budget is spent)."""


def ending(status: int, stopped: bool, executor: ServiceProcess, faults: list[str],
           out: Callable[[str], None]) -> tuple[int, bool]:
    """The run's exit status, and whether it went to its end (the executor finished it); what is wrong said in a line.

    Args:
        status: What the watch found (1: a timeout, a service dead at start, a fatal fault; 0: the executor ended).
        stopped: A stop was requested (Ctrl-C, SIGTERM).
        executor: The run's executor process (ended, or still running after a stop, a timeout or a fault).
        faults: The supervisor's faults as words (``planner (killed)``).
        out: Where to say it.

    An incomplete log (4) is said by the closing ``MCAP log:`` line; it wins over a run not whole (1), as the
    executor's own status does. Before, it and a real-time run that lost a service ended with status 0, and a run
    whose ticks went on without their plan was "stopped after 19 of 20 steps" with the executor's ``mcap: PATH`` line
    given as the reason (a review).
    """
    code = executor.returncode
    finished = code in (0, INCOMPLETE, LOG_INCOMPLETE)
    if stopped and not (finished and status == 0):  # (a Ctrl-C just after the last step: it had finished)
        out("foresight demo: interrupted; stopping the services (the executor first: it closes the log)")
        return 130, False
    if code == INCOMPLETE:  # its last line is the log's path, no reason: the executor's log names the service
        out("foresight demo: the run went to its end, but some of its ticks went on without their plan or prediction "
            f"(a service was gone: {executor.log_path} says which, and how many ticks); not the run its seed makes")
    elif code is not None and not finished:
        said = executor.last_words()  # a killed process's last line is not why it died: only an error's is
        out(f"foresight demo: executor {describe_exit(code)}" + (f": {said}" if said else ""))
        status = 1
    if faults:
        out("foresight demo: faults during the run: " + ", ".join(faults))
    if status:
        return status, False
    if code == LOG_INCOMPLETE:
        return LOG_INCOMPLETE, True
    return (1 if faults or code == INCOMPLETE else 0), True


def stop_in_order(procs: Mapping[str, ServiceProcess], order: Sequence[str], wanted_s: float,
                  budget_s: float = STOP_BUDGET_S, clock: Callable[[], float] | None = None
                  ) -> Iterator[tuple[str, int | None]]:
    """Stop ``procs`` in ``order``, each given up to ``wanted_s`` after its SIGTERM; yields ``(name, status)``.

    All take their waits from one deadline, ``budget_s`` from now: the first (the executor, closing its log) gets its
    whole grace, later ones what is left (at least 0.5 s, then 1 s after their SIGKILL).
    """
    now = clock or time.monotonic
    deadline = now() + budget_s
    for name in order:
        timeout = max(0.5, min(wanted_s, deadline - now()))
        kill_wait = max(1.0, min(KILL_WAIT_S, deadline - now() - timeout))
        yield name, stop_service(procs[name], timeout, kill_wait)
