"""Which of a real-time run's plans the executor adopted, from when each arrived and when its states were made.

The real-time executor (:mod:`services.executor.realtime`) takes the newest plan it has received at each robot
state, just before it makes it: a plan is adopted by the first state made after it arrived, unless a newer plan
arrived first (then it was never executed), and one that arrived after the run's last state never was. Its log has
both clocks: a plan's log time is when the executor received it, a state's stamp the wall time it was made at.

Counted by this rule, a run's summary, ``foresight log table`` and ``foresight log render`` give the executor's
own ``N plans adopted``. The rule they used before kept every plan stamped before the robot's last state: an
interrupted run said "interrupted after 11 plans" where the executor had adopted 9 (a review).
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

__all__ = ["adopted"]


def adopted(received: Sequence[float], state_stamps: Sequence[float]) -> list[bool]:
    """Whether each plan was adopted, by the executor's real-time rule (see the module's docstring).

    Args:
        received: When each plan arrived (s, wall clock; the executor's log time), in arrival order.
        state_stamps: The robot states' stamps (s, wall clock), any order.

    Returns:
        One flag per plan of ``received``.
    """
    stamps = sorted(state_stamps)
    out = []
    for i, t in enumerate(received):
        j = bisect.bisect_left(stamps, t)  # the first state made after the plan arrived
        newer = received[i + 1] if i + 1 < len(received) else None
        out.append(j < len(stamps) and (newer is None or newer > stamps[j]))
    return out
