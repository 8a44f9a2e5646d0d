"""``foresight log table``: a logged run's step table and outcome, as ``foresight demo`` printed it live.

The plans, robot states, final occupancy and class posteriors of the MCAP go through the same summary as the
demo's (:func:`services.scenario.summarise`): one row per replanning step (time, chosen goal, each goal's
cost, planning time; real time: per plan the executor adopted, :mod:`services.adopted_plans`), the switch step,
whether and when the goal was reached, the interference cost. Two runs of one scenario -- ``foresight demo`` and
``docker compose up``, say -- compare by their tables.
"""

from __future__ import annotations

from services.run_log import RunRecorder
from services.scenario import Summary, summarise
from shared.protocol import ClassPosterior, OccupancyGrid, Plan, RobotState
from shared.recording.reader import LogFile

from .steps import decode_all, scene_of

__all__ = ["WANTED", "run_summary", "table_lines"]

WANTED = {"foresight.Plan", "foresight.RobotState", "foresight.OccupancyGrid", "foresight.ClassPosterior"}
"""The channels (schemas) the table is made from."""


def run_summary(lf: LogFile) -> Summary:
    """The run's summary from its log (read with the :data:`WANTED` channels kept)."""
    import torch

    from shared.robot import PR2

    recorder = RunRecorder()  # the demo's own rules: the newest grid, posteriors by tick or arrival (run_log.py)
    for cls in (Plan, RobotState, OccupancyGrid, ClassPosterior):
        for log_time, msg in decode_all(lf, f"foresight.{cls.TYPE}", cls, required=cls is Plan):
            recorder.on_message(msg, log_time / 1e9)  # a plan's: when the executor received it
    plans, states, final, posteriors = recorder.snapshot()
    robot = PR2.from_scene(scene_of(lf), device="cpu", dtype=torch.float32)
    return summarise(plans, states, final, posteriors, robot, "", lf.path, received=recorder.plan_arrivals())


def table_lines(summary: Summary) -> list[str]:
    """The table, then the switch step, the goal reached, the interference cost (no human class: not logged)."""
    return [line for line in summary.lines() if not line.startswith(("human class:", "MCAP log:"))]
