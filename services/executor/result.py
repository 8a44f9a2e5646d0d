"""What an executor run did: :class:`ExecutorResult` (``ExecutorService.run`` returns it)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ExecutorResult", "INCOMPLETE", "LOG_INCOMPLETE"]

INCOMPLETE = 1
"""Exit status of a lock-step run that finished with ticks that went on without their plan or prediction."""

LOG_INCOMPLETE = 4
"""The executor's exit status when its MCAP log lost messages (a full disk): its ``mcap:`` line says how many.

Here, not in ``__main__`` (nor :data:`INCOMPLETE`): ``foresight demo`` reads them without importing the
executor's service.
"""


@dataclass
class ExecutorResult:
    """What a run did.

    Attributes:
        steps: Replanning steps completed (lock-step) or periods elapsed (real time).
        reached: Whether a goal was reached; ``reached_step`` the first step one was (-1: never);
            ``reached_steps`` the first step each goal (index) was, where the robot switched goals.
        goal_per_step: Goal index executed during each step (-1: none yet).
        held_steps: Steps (lock-step) or state samples (real time) during which the robot held.
        separation_holds: Of those, the state samples held by the separation guard (real time: a step would have
            closed in on the person within ``separation.stop_m``).
        lockstep_timeouts: Lock-step waits for a tick's plan or prediction that ran out (the step went on without
            it: a run whose numbers depend on timing; the experiments refuse such a run).
        finish_steps: Steps after the last one that executed the rest of the last plan (``finish_path``), or, in
            real time, periods after the run's length on the way to the goal (``finish_s``; ``goal_per_step`` has
            them too).
        plans: Plans adopted; ``plans_rejected``: plans with the wrong joints.
        rejects: Payloads refused (decoding, values, order), per key; ``reject_reasons`` per
            ``"key reason"``.
        mcap_path: The log, or None; ``log_write_failures``: writes to it that failed (a full disk: messages refused
            once the file had ended, flushes, the close).
        log_incomplete: The close's one line when the log is not complete (``<path>: INCOMPLETE: N of M messages
            written (why)``; '' when it is); ``log_lost`` those M - N messages; ``log_dropped_after_close``: messages
            given to the log after its close (not written).
        times: ``(N,)`` stamps of the published states; ``q``: ``(N, D)`` their configurations.
    """

    steps: int = 0
    reached: bool = False
    reached_step: int = -1
    reached_steps: dict[int, int] = field(default_factory=dict)
    goal_per_step: list[int] = field(default_factory=list)
    held_steps: int = 0
    separation_holds: int = 0
    lockstep_timeouts: int = 0
    finish_steps: int = 0
    plans: int = 0
    plans_rejected: int = 0
    rejects: dict[str, int] = field(default_factory=dict)
    reject_reasons: dict[str, int] = field(default_factory=dict)
    log_write_failures: int = 0
    log_incomplete: str = ""
    log_lost: int = 0
    log_dropped_after_close: int = 0
    mcap_path: str | None = None
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def final_goal(self) -> str:
        """The run's last goal and whether it was reached, in words: ``goal 1 reached during step 12``.

        The closing line put the first reach of any goal beside the last goal: "goal 1 reached during step 9" where
        only goal 0 had been (a review). Now ``goal 1 not reached (goal 0 was, during step 9)``.
        """
        if not self.goal_per_step:
            return "goal none"
        final = self.goal_per_step[-1]
        if final in self.reached_steps:
            return f"goal {final} reached during step {self.reached_steps[final]}"
        others = ", ".join(f"goal {g} was, during step {n}" for g, n in sorted(self.reached_steps.items()))
        return f"goal {final} not reached" + (f" ({others})" if others else "")

    def note_reached(self, goal: int, step: int) -> bool:
        """Goal ``goal`` is reached during ``step``; True the first time any goal is (the run's ``reached_step``)."""
        self.reached_steps.setdefault(goal, step)
        if self.reached_step >= 0:
            return False
        self.reached, self.reached_step = True, step
        return True
