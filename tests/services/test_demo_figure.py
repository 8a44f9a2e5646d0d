"""The demo's PNG: drawn from measured outcomes, with or without a prediction and a human."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from services.demo_figure import draw_outcomes
from services.demo_outcome import Outcome
from shared.protocol import HumanPose, OccupancyGrid
from shared.scene import load_scene

PNG = b"\x89PNG\r\n\x1a\n"


def _outcome(name: str, goals: list[str]) -> Outcome:
    t = np.linspace(0.0, 2.0, 21)
    ee = np.stack([0.5 - 0.02 * np.arange(21), np.full(21, -0.7), np.full(21, 0.8)], -1)
    return Outcome(name, 0.5, 0.0, 0.1, 0.02, 2, 15, goals, t, ee, np.linspace(0.3, 0.02, 21))


def test_draws_one_png_for_one_or_three_planners(tmp_path: Path) -> None:
    scene = load_scene("pr2_two_cups_side")
    dense = np.zeros(scene.grid.dims)
    dense[10:14, 10:14, 5:9] = 0.8
    grid = OccupancyGrid.from_dense(dense, scene.grid.origin, scene.grid.resolution, stamp=0.0, tick=0,
                                    tick_last=True, demo_id=0, index=0, method="prediction")
    feats = np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])
    poses = [HumanPose(stamp=0.1 * i, tick=i, tick_last=True, demo_id=1, index=i, features=feats + 0.01 * i)
             for i in range(10)]
    three = [_outcome("prediction", ["blue_cup", "red_cup"] + ["red_cup"] * 2),
             _outcome("current occupancy", ["blue_cup"] * 4), _outcome("no human cost", ["blue_cup"] * 4)]
    out = draw_outcomes(three, scene, grid, poses, tmp_path / "three.png", period_s=0.5, title="three")
    assert out.read_bytes()[:8] == PNG
    one = draw_outcomes(three[:1], scene, None, [], tmp_path / "sub" / "one.png", period_s=0.5)
    assert one.read_bytes()[:8] == PNG and one.parent.name == "sub"


def test_step_marks_follow_the_runs_own_clock_in_real_time() -> None:
    """Real-time states are stamped with the wall clock: the step marks all sat on the first point."""
    import time

    from services.demo_figure import _step_points

    n = 40
    ee = np.c_[np.arange(n), np.zeros(n), np.zeros(n)].astype(float)
    for t0 in (0.0, time.time()):
        o = Outcome("p", 0.0, 0.0, 0.0, 1.0, None, None, ["red_cup"] * 3, t0 + np.arange(n) * 0.1, ee, np.zeros(n))
        assert _step_points(o, 0.5)[:, 0].tolist() == [0.0, 5.0, 10.0]


def test_plan_marks_sit_where_each_plan_was_made() -> None:
    """A real-time planner replans as each prediction comes (100 plans in 10 s): the marks, one a period apart,
    put plans 20-99 at the path's end."""
    from services.demo_figure import _step_points

    n = 100  # states 0.1 s apart, the hand at x = 0.1 t
    ee = np.c_[np.arange(n) * 0.01, np.zeros(n), np.zeros(n)]
    plans = np.array([0.0, 0.05, 0.15, 0.25, 1.95, 8.95])  # between states: the next one
    o = Outcome("p", 0.0, 0.0, 0.0, 1.0, None, None, ["red_cup"] * 6, 100.0 + np.arange(n) * 0.1, ee, np.zeros(n),
                unit="plan", plan_t_s=plans)
    assert np.allclose(_step_points(o, 0.5)[:, 0], [0.0, 0.01, 0.02, 0.03, 0.2, 0.9])


def _drawn(outcomes: list[Outcome], out: Path, monkeypatch) -> object:
    """The matplotlib figure ``draw_outcomes`` writes (closed once written; its axes and layout as written)."""
    import matplotlib

    matplotlib.use("Agg")
    from services import demo_figure

    figs: list = []
    real_save = demo_figure.save_figure

    def keep(fig: object, path: Path) -> Path:
        figs.append(fig)
        return real_save(fig, path)

    monkeypatch.setattr(demo_figure, "save_figure", keep)
    demo_figure.draw_outcomes(outcomes, load_scene("pr2_two_cups_side"), None, [], out, 0.5)
    (fig,) = figs
    return fig


def test_a_real_time_figure_counts_plans(tmp_path: Path, monkeypatch) -> None:
    """Its goal lane and top view say "plan", not "replanning step"."""
    o = _outcome("prediction", ["red_cup"] * 4)
    o.unit, o.plan_t_s = "plan", np.array([0.0, 0.1, 0.2, 0.3])
    fig = _drawn([o], tmp_path / "rt.png", monkeypatch)
    seen = {ax.get_title(): ax.get_xlabel() for ax in fig.axes}  # type: ignore[attr-defined]
    assert seen["goal chosen at each plan (square colour = cup)"].startswith("plan (")
    assert any(t.startswith("top view") and "each plan," in t for t in seen)


def test_an_interrupted_run_draws_only_the_poses_it_saw() -> None:
    """Ctrl-C at 1.35 s: the replayer went on while the services stopped, and the figure drew the whole reach."""
    from services.demo_figure import poses_of_the_run

    feats = np.zeros(12)
    poses = [HumanPose(stamp=0.1 * i, tick=-1, tick_last=True, demo_id=0, index=i, features=feats) for i in range(40)]
    run = _outcome("prediction", ["red_cup"] * 3)  # its states end at 2.0 s
    assert [p.index for p in poses_of_the_run(poses, [run])] == list(range(21))
    assert poses_of_the_run(poses, []) == poses  # no state: every pose


def test_the_top_views_legend_lies_off_the_paths(tmp_path: Path, monkeypatch) -> None:
    """Placed "best" inside the view, the legend lay on the robot's path and the cups (a real-time run's PNG)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    three = [_outcome(n, ["red_cup"] * 4) for n in ("prediction", "current occupancy", "no human cost")]
    fig = _drawn(three, tmp_path / "legend.png", monkeypatch)
    top = next(ax for ax in fig.axes if ax.get_title().startswith("top view"))  # type: ignore[attr-defined]
    renderer = FigureCanvasAgg(fig).get_renderer()  # closed once written: a canvas again, the layout as written
    legend = top.get_legend().get_window_extent(renderer)
    assert legend.height > 0 and not legend.overlaps(top.get_window_extent(renderer))
    assert not any(legend.overlaps(ax.get_window_extent(renderer)) for ax in fig.axes  # type: ignore[attr-defined]
                   if ax is not top)


def test_a_long_title_is_wrapped_inside_the_figure(tmp_path: Path, monkeypatch) -> None:
    """A --compare run cut short in its second planner: its 203-character title ran off both edges of run.png."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from services import demo_figure

    title = ("foresight demo: far_left reach, scene pr2_two_cups_side, robot at 0.5 of its velocity limits, 10 s in "
             "real time, 100 plans (the prediction planner's): the current occupancy planner's run was interrupted")
    assert len(title) >= 200
    figs: list = []
    real_save = demo_figure.save_figure
    monkeypatch.setattr(demo_figure, "save_figure", lambda fig, path: figs.append(fig) or real_save(fig, path))
    demo_figure.draw_outcomes([_outcome("prediction", ["red_cup"] * 4)], load_scene("pr2_two_cups_side"), None, [],
                              tmp_path / "long.png", 0.5, title=title)
    (fig,) = figs
    suptitle = fig._suptitle  # type: ignore[attr-defined]
    assert 2 <= len(suptitle.get_text().splitlines()) <= 3 and " ".join(suptitle.get_text().split()) == title
    renderer = FigureCanvasAgg(fig).get_renderer()
    box, page = suptitle.get_window_extent(renderer), fig.bbox  # type: ignore[attr-defined]
    assert page.x0 <= box.x0 and box.x1 <= page.x1 and box.y1 <= page.y1
    assert not any(box.overlaps(ax.get_window_extent(renderer)) for ax in fig.axes)  # type: ignore[attr-defined]
