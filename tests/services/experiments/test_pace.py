"""``foresight eval pace``'s verdicts from its points (the sweep itself runs in test_harness)."""

from __future__ import annotations

import dataclasses

from services.experiments.pace import PaceConfig, PacePoint, PaceResult


def point(pace: float, basic: float, lp: float) -> PacePoint:
    row = {"min_clearance_m": 0.1, "reached_step": 10.0, "interference": 1.0}
    return PacePoint("product", "synthetic", pace, 2.0, {"basic": {**row, "contact_s": basic},
                                                         "least_penetration": {**row, "contact_s": lp}})


def result(*points: PacePoint) -> PaceResult:
    return PaceResult(PaceConfig(protocols=("product",)), list(points))


def test_the_pace_from_which_prediction_no_longer_lowers_contact():
    res = result(point(0.05, 1.0, 0.0), point(0.1, 0.8, 0.2), point(0.25, 0.4, 0.4), point(0.5, 0.0, 0.0))
    assert [ok for _, ok in res.pays("product", "synthetic")] == [True, True, False, None]
    verdict = res.verdict("product", "synthetic")
    assert "lowers the contact at pace 0.05, 0.1; from pace 0.25 on it no longer does" in verdict
    assert verdict.endswith("touches longer than basic STOMP at no pace")


def test_touching_longer_and_never_touching_are_named():
    res = result(point(0.1, 0.0, 0.3), point(0.2, 0.0, 0.0))
    assert "lowers the contact at no pace" in res.verdict("product", "synthetic")
    assert res.verdict("product", "synthetic").endswith("at 0.1")
    assert res.verdict("product", "synthetic").startswith("least penetration")
    none = result(point(0.1, 0.0, 0.0))
    # of its sample: Table I at the same pace (5 x 10 runs) touched the human where the sweep's 3 x 1 did not
    assert none.verdict("product", "synthetic").startswith("neither planner touches the human at any pace in these "
                                                           "5 x 2 runs per pace")
    assert none.to_json()["verdicts"] == {"product, synthetic": none.verdict("product", "synthetic")}


def test_the_product_protocol_sweeps_with_the_volume_asked_for_and_the_report_passes_it(monkeypatch, tmp_path):
    """``eval all --volume V`` ran Table I and the switch with V but the pace sweep with the trainer's default."""
    import types

    from services.experiments import pace, sections
    from services.experiments.report import QUICK

    asked = []

    def fake_interference(cfg, progress=None, compile=True):
        asked.append((cfg.protocol, cfg.volume))
        assert cfg.draw == 5  # Table I's first demonstrations
        return types.SimpleNamespace(ratio=lambda: float("nan"))

    monkeypatch.setattr(pace, "run_interference", fake_interference)
    monkeypatch.setattr(pace, "_point", lambda res, prot, lib, p: point(p, 0.0, 0.0))
    pace.run_pace(PaceConfig(protocols=("product", "paper"), paces={"product": (0.25,), "paper": (0.05,)},
                             volume="spread"), progress=lambda _: None)
    assert asked == [("product", "spread"), ("paper", None)]  # the paper protocol keeps its own volume
    seen = []
    monkeypatch.setattr(sections, "run_pace",
                        lambda cfg, say, compile: seen.append((cfg.volume, cfg.draw)) or PaceResult(cfg))
    sections.library_part("synthetic", "product:pace", QUICK, tmp_path, tmp_path / "models", volume="spread")
    assert seen == [("spread", QUICK.table1_demos)]  # the report's Table I's draw


def test_a_sweep_without_a_finite_positive_ratio_is_drawn(tmp_path):
    """A sweep of one pace where both planners scored 0 (ratio 0 / 0) ended in 'Data cannot be log-scaled'."""
    from services.experiments.pace import plot_pace

    nan = dataclasses.replace(point(0.1, 0.0, 0.0), ratio=float("nan"))
    zero = dataclasses.replace(point(0.2, 0.0, 0.0), ratio=0.0)
    for points in ([nan], [nan, zero], [nan, zero, dataclasses.replace(point(0.3, 0.0, 0.0), ratio=float("inf"))],
                   [nan, point(0.3, 1.0, 0.0)]):
        png = plot_pace(result(*points), tmp_path / f"pace{len(points)}.png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_pace_sweeps_demonstrations_are_table_is_first() -> None:
    """A draw of 3 was no part of Table I's draw of 5 (seed 0: [12, 15, 19] against [6, 7, 11, 14, 17]): the sweep
    at Table I's pace said no planner touched the human where Table I's basic STOMP did, on #6."""
    from services.experiments.interference import draw_demos
    from services.experiments.report import FULL

    table1 = draw_demos(25, 5, 0)
    assert table1 == [6, 7, 11, 14, 17]  # Table I's own draw is what it was
    pace = draw_demos(25, 3, 0, draw=5)
    assert set(pace) < set(table1) and len(pace) == 3
    assert PaceConfig().draw == 5 and FULL.table1_demos == 5  # the report's sweep draws as its Table I does
    for seed in range(20):  # any pool and count: the first of the larger draw, never past the pool
        assert set(draw_demos(9, 2, seed, draw=20)) <= set(draw_demos(9, 8, seed)) and len(draw_demos(9, 2, seed)) == 2


def test_the_pace_picture_keeps_a_colour_per_library_readable_ticks_and_names_what_it_cannot_draw(
        tmp_path, monkeypatch) -> None:
    """Orange was the synthetic library in the ratio row and the paper's least penetration below; the paper
    column's log ticks ran into each other; ratios 0 / 0 and inf were dropped without a word."""
    import matplotlib.colors as mcolors

    from services.experiments import plots
    from services.experiments.pace import plot_pace

    pts = []
    for lib in ("synthetic", "paper-library"):
        for pace, ratio in ((0.0125, float("inf")), (0.025, 3.0), (0.05, float("nan"))):
            pts.append(dataclasses.replace(point(pace, 1.0, 0.0), protocol="paper", library=lib, ratio=ratio))
    res = PaceResult(PaceConfig(protocols=("paper",)), pts)
    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figures.append(fig) or path)
    plot_pace(res, tmp_path / "pace.png")
    ratio_ax, contact_ax, reached_ax = figures[0].axes
    for ax in (ratio_ax, contact_ax, reached_ax):
        colours = {}
        for line in ax.get_lines():
            lib = line.get_label().split(",")[0]
            if lib in ("synthetic", "paper-library"):
                colours.setdefault(lib, set()).add(mcolors.to_hex(line.get_color()))
        assert all(len(c) == 1 for c in colours.values()) and len(set().union(*colours.values())) == 2
    assert [t.get_text() for t in reached_ax.get_xticklabels()] == ["0.0125", "0.025", "0.05"]
    note = " ".join(t.get_text() for t in ratio_ax.texts)
    assert "synthetic 0.0125: inf" in note and "paper-library 0.05: n/a (0 / 0)" in note
    import matplotlib.pyplot as plt

    plt.close(figures[0])


def test_a_sweep_of_one_pace_at_the_operating_point_is_drawn_where_it_can_be_seen(tmp_path, monkeypatch) -> None:
    """`eval all --quick` sweeps each protocol at its own pace only: the log axis shrank to (0.2499..., 0.25) and the
    product column showed no point at all (a review)."""
    from services.experiments import plots
    from services.experiments.pace import OPERATING_POINT, plot_pace

    pace = OPERATING_POINT["product"]
    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figures.append(fig) or path)
    plot_pace(result(point(pace, 1.0, 0.0)), tmp_path / "pace.png")
    for ax in figures[0].axes:
        lo, hi = ax.get_xlim()
        assert lo <= pace / 1.9 and hi >= pace * 1.9, (lo, hi)


def test_the_sweep_passes_a_classs_warning_on_once(monkeypatch):
    """Only lines starting "  [" were passed on: the paper's library's "warning: class compound_1's mean reach ends
    0.45 m from blue_cup" never reached `eval pace` or `eval all`."""
    import types

    from services.experiments import pace

    warning = "warning: class compound_1's mean reach ends 0.45 m from blue_cup, more than 0.3: ..."

    def fake_interference(cfg, progress=None, compile=True):
        progress("interference (paper protocol): the library, scene ...; demonstrations [0] (held out)")
        progress(warning)
        progress("  [1/2] demo #0 seed 0 basic STOMP        interference    0.008")
        return types.SimpleNamespace(ratio=lambda: float("nan"))

    monkeypatch.setattr(pace, "run_interference", fake_interference)
    monkeypatch.setattr(pace, "_point", lambda res, prot, lib, p: point(p, 0.0, 0.0))
    said: list[str] = []
    pace.run_pace(PaceConfig(protocols=("paper",), paces={"paper": (0.05, 0.1)}), progress=said.append)
    assert said.count(f"  {warning}") == 1  # once, not once per pace
    assert not any("interference (paper protocol)" in line for line in said)  # the point's line says where
    assert said.count("    [1/2] demo #0 seed 0 basic STOMP        interference    0.008") == 2
