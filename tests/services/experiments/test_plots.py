"""Table I's picture: the unit of its protocol, error bars that stop at 0, every run's dot left in view."""

from __future__ import annotations

import pytest

from services.experiments import plots
from services.experiments.heldout import CupClass
from services.experiments.interference import InterferenceConfig, InterferenceResult
from services.experiments.scoring import RunScore


@pytest.mark.parametrize("protocol, unit", [("product", "(p-voxel s)"), ("paper", "(p-voxel x C-space length)")])
def test_table_i_picture_says_its_protocols_unit_and_hides_nothing(protocol, unit, tmp_path, monkeypatch) -> None:
    """The paper protocol's picture said p-voxel s for a path integral, its error bars went below 0 (-0.25 for
    an interference that cannot be negative), and the legend covered a run's clearance dot (a new user's run)."""
    res = InterferenceResult(InterferenceConfig(protocol=protocol, demos=1, seeds=2), "synthetic",
                             CupClass("blue_cup", 0, "blue_cup", 0.0), [0])
    for seed, value in enumerate((0.1, 0.9)):  # mean 0.5, sample std 0.57: the bar's lower end would be -0.07
        for name in ("basic", "least_penetration", "current"):
            res.runs.append(RunScore(0, seed, name, value, 0.0, 0.0, 0.1, 0.0, 0.0, None, (), 30.0))
    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figures.append(fig) or path)
    plots.plot_interference(res, tmp_path / "t.png")
    top, bottom = figures[0].axes
    assert top.get_ylabel().endswith(unit)
    lows = [min(p[1] for p in seg) for bars in top.collections for seg in bars.get_segments()]  # the error bars
    assert lows and min(lows) >= 0.0
    assert bottom.get_legend() is None and top.get_legend().get_bbox_to_anchor().x0 >= top.get_window_extent().x1
    import matplotlib.pyplot as plt  # plot_interference chose the Agg backend

    plt.close(figures[0])


def test_fig9_marks_the_step_the_verdict_times_not_the_settle_step(tmp_path, monkeypatch) -> None:
    """The dashed line was the median settle step (current at 7, the mean of 14 and 0) while the verdict timed the
    step each planner leaves the human's cup (17 against 6)."""
    from services.experiments.switch import SwitchConfig, SwitchResult, SwitchRun, plot_switch

    res = SwitchResult(SwitchConfig(), "synthetic", CupClass("red_cup", 1, "red_cup", 0.0))
    costs = tuple((1.0, 2.0) for _ in range(20))
    for method, settles, aways in (("current", (14, 0), (17, 17)), ("prediction", (5, 5), (6, 6))):
        for demo, (settle, away) in enumerate(zip(settles, aways, strict=True)):
            res.runs.append(SwitchRun(demo, method, ("red_cup",) * away + ("blue_cup",) * (20 - away),
                                      ("blue_cup", "red_cup"), costs, costs, settle, away, "blue_cup", None, 0.1, 0.0,
                                      30.0))
    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figures.append(fig) or path)
    plot_switch(res, tmp_path / "f.png")
    current, prediction = (ax.get_legend_handles_labels()[1] for ax in figures[0].axes)
    assert "median step it leaves red_cup: 17" in current and "median step it leaves red_cup: 6" in prediction
    assert not any("settle" in label for label in (*current, *prediction))
    import matplotlib.pyplot as plt

    plt.close(figures[0])
