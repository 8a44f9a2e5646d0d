"""``python -m services.executor`` / ``foresight executor``: simulate the PR2 and log the run to MCAP."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.native_threads import limit_torch_threads
from shared.runtime import service_main
from shared.security.acl import refuse_ros2_keys

from .core import ExecutorConfig
from .result import INCOMPLETE, LOG_INCOMPLETE
from .service import ExecutorService

__all__ = ["main", "INCOMPLETE", "LOG_INCOMPLETE"]

DESCRIPTION = """Simulate the PR2 arm following the chosen trajectory of the latest Plan (within its
joint and velocity limits; the plan of replanning step n-1 runs during step n), publish RobotState,
hold the robot when plans or predictions go stale, and log every message under the key prefix to an
MCAP file (plus Foxglove 3D channels). In lock-step mode the executor is the simulation master and
emits the ClockTicks. Stops after --steps, or on SIGINT/SIGTERM (the MCAP file is finalised either
way). Options come from the dataclass defaults < --config FILE ([executor], [zenoh]) < env
FORESIGHT_EXECUTOR_<NAME> / FORESIGHT_ZENOH_<NAME> < flags. Exit status 1: a lock-step run finished with
ticks that went on without their plan or prediction (a service gone mid-run), not the run its seed makes;
4: the MCAP log is not complete (a full disk: its last line, `mcap: PATH: INCOMPLETE: N of M messages
written (why)`, says how many were lost)."""


SWITCH_INTERVAL_S = 0.001
"""The executor process's GIL switch interval (Python's default: 5 ms).

Its Zenoh callback receives the plans while the Foxglove thread builds and encodes updates (an
occupancy: ~13 ms of Python and JSON, in slices): a thread waiting for the GIL gets it after at most
this long, so a plan is received (and stamped) within ~1.5 ms of its arrival instead of ~5.5 ms.
"""


def _make(cfg: ExecutorConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    if cfg.robot == "ros2":  # before anything starts: the robot's keys would be dropped by every peer
        refuse_ros2_keys(zcfg.security_dir, "foresight executor --robot ros2")
    sys.setswitchinterval(SWITCH_INTERVAL_S)  # this process only: `python -m services.executor`
    limit_torch_threads(1)  # its torch work is the scene's forward kinematics: a second thread only spins
    service = ExecutorService(cfg, zcfg, stop)

    def run() -> int:
        result = service.run()
        if result.mcap_path:  # a log a full disk cut short: said in this line (it ended 'mcap: PATH', status 0)
            try:
                print(f"mcap: {result.log_incomplete or result.mcap_path}", flush=True)
            except OSError:  # the same full disk under its output (ENOSPC): the line is lost, the status must stand
                pass  # (it raised, and status 4 became 1: `foresight demo` then said "not an MCAP file")
        if result.log_incomplete:
            return LOG_INCOMPLETE
        # a lock-step run whose ticks went on without their plan or prediction is not the run its seed makes: a
        # planner killed mid-run ended 'done ... reached=True', status 0, and compose and scripts took it for one
        return INCOMPLETE if result.lockstep_timeouts else 0

    return run


def main(argv: list[str] | None = None, prog: str = "python -m services.executor") -> int:
    """Run the executor; returns the exit status (0 done or stopped, 1 :data:`INCOMPLETE`, 2 bad input, 4 its log's).

    4 is :data:`LOG_INCOMPLETE`: the MCAP log lost messages (a full disk).
    """
    return service_main(argv, prog, section="executor", config_cls=ExecutorConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
