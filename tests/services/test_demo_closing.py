"""The demo's closing lines: how to render what the run logged."""

from __future__ import annotations

import dataclasses

import pytest


@pytest.mark.parametrize(("mode", "each"), [("lockstep", "step"), ("realtime", "plan")])
def test_the_render_hint_names_plans_for_a_real_time_run(mode: str, each: str) -> None:
    """A real-time run's hint said "each step: ... --step N": render numbers its plans, not steps (a review)."""
    from services.demo import DemoConfig
    from services.demo_closing import closing_lines
    from services.scenario import Summary

    summary = Summary(steps=[], chosen_goal_per_step=[], switch_step=None, interference_cost=0.0, mcap_path="x.mcap",
                      reached=True, reached_step=None, human_class="blue_cup", recognised_class="blue_cup",
                      extra={"run_dir": "runs/demo/x"})
    lines = closing_lines(dataclasses.replace(DemoConfig(), mode=mode), summary)
    assert lines[-1] == (f"this run's logs: runs/demo/x/ (each {each}: foresight log render x.mcap --step N --out "
                         f"{each}.png)")
