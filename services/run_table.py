"""The run's table: one row per plan (lock-step: per step), as the demo prints it live and ``foresight log table``.

Moved out of :mod:`services.scenario` (which re-exports them), where the summary is made.
"""

from __future__ import annotations

from typing import Any

from shared.protocol import Plan

__all__ = ["step_entry", "table_header", "table_row"]


def step_entry(plan: Plan, t0: float, step: int | None = None) -> dict[str, Any]:
    """One row of the run's table (and of ``--json``'s ``steps``) for ``plan``.

    Args:
        plan: The plan.
        t0: Start of the run on the plans' clock (0 in lock-step; the executor's first state in real time).
        step: The row's number (default: the tick in lock-step, the planner's own step count in real time).

    Returns:
        ``step``, ``tick`` (-1 in real time), ``t_s`` (seconds into the run the plan was made), ``chosen``,
        ``planning_ms``, ``occupancy_tick``, and ``cost_total`` / ``cost_human`` by goal name for the valid goals.
    """
    names = list(plan.goal_names)
    if step is None:  # the tick in lock-step: a restarted planner counts its own steps from 0 again
        step = plan.tick if plan.tick >= 0 else plan.step
    return {"step": step, "tick": plan.tick, "t_s": float(plan.stamp - t0), "chosen": names[plan.chosen],
            "planning_ms": plan.planning_ms, "occupancy_tick": plan.occupancy_tick,
            "cost_total": {n: float(c) for n, c, v in zip(names, plan.cost_total, plan.valid, strict=True) if v},
            "cost_human": {n: float(c) for n, c, v in zip(names, plan.cost_human, plan.valid, strict=True) if v}}


def table_header(goal_names: list[str], unit: str = "step") -> str:
    """The header of the run's table (one column per goal's total cost).

    ``unit``: what a row is (a real-time run's rows are its plans, several a replanning step).
    """
    return (f"{unit:>4} {'t (s)':>6}  {'chosen':<12}" + "".join(f"{'cost ' + n:>16}" for n in goal_names)
            + f"{'plan ms':>9}  human (belief)")


def table_row(entry: dict[str, Any], goal_names: list[str], belief: str = "") -> str:
    """One row of the run's table for a :func:`step_entry` (invalid goals: ``invalid``)."""
    costs = "".join(f"{entry['cost_total'][n]:>16.3f}" if n in entry["cost_total"] else f"{'invalid':>16}"
                    for n in goal_names)
    return (f"{entry['step']:>4} {entry['t_s']:>6.2f}  {entry['chosen']:<12}{costs}{entry['planning_ms']:>9.0f}"
            + (f"  {belief}" if belief else "")).rstrip()
