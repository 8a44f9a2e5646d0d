"""The switch experiment's reached step is the final goal's, not the first goal reached."""

from __future__ import annotations

from services.executor.result import ExecutorResult
from services.experiments.switch import final_reached


def test_the_reached_step_is_the_final_goals() -> None:
    """A robot that reached the blue cup at step 10 and turned to the red one at step 14 was reported 'red_cup,
    reached step 10' (eval all --quick)."""
    r = ExecutorResult()
    r.note_reached(0, 10)
    chosen = ["blue_cup"] * 14 + ["red_cup"] * 6
    assert final_reached(r, ["blue_cup", "red_cup"], chosen) is None  # red never reached
    r.note_reached(1, 19)
    assert final_reached(r, ["blue_cup", "red_cup"], chosen) == 19
    assert final_reached(r, ["blue_cup", "red_cup"], chosen[:10]) == 10  # ended going for blue
    assert final_reached(None, ["blue_cup"], chosen) is None and final_reached(r, ["blue_cup"], []) is None


def test_the_switch_json_says_the_volume_and_iterations_that_ran() -> None:
    """Its JSON said "volume": null and "iterations": null where the paper protocol ran `paper` and 51."""
    from services.experiments.heldout import CupClass
    from services.experiments.switch import SwitchConfig, SwitchResult

    data = SwitchResult(SwitchConfig(protocol="paper"), "synthetic", CupClass("red_cup", 1, "red_cup", 0.0)).to_json()
    assert data["volume"] == "paper" and data["timing"]["iterations"] == 51


def test_a_run_short_of_its_goal_is_worded_not_printed_as_none() -> None:
    """eval all --quick printed 'final red_cup  reached step None' for a run that never reached its final goal."""
    from services.experiments.heldout import CupClass
    from services.experiments.switch import SwitchConfig, SwitchResult, SwitchRun, run_line

    def run(reached: int | None) -> SwitchRun:
        return SwitchRun(0, "current", ("blue_cup",) * 14 + ("red_cup",) * 6, ("blue_cup", "red_cup"), (), (), 14,
                         14, "red_cup", reached, 0.1, 0.0, 5.0)

    line = run_line(run(None))
    assert "None" not in line and line.endswith("final red_cup  not at its goal by the run's end")
    assert "goals bbbbbbbbbbbbbbrrrrrr" in line and run_line(run(19)).endswith("reached step 19")
    result = SwitchResult(SwitchConfig(), "synthetic", CupClass("red_cup", 1, "red_cup", 0.0), runs=[run(None)])
    assert "/ red_cup / not reached" in "\n".join(result.lines())
