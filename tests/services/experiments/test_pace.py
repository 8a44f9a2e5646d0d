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
    assert none.verdict("product", "synthetic").startswith("neither planner touches the human at any pace")
    assert none.to_json()["verdicts"] == {"product, synthetic": none.verdict("product", "synthetic")}


def test_the_product_protocol_sweeps_with_the_volume_asked_for_and_the_report_passes_it(monkeypatch, tmp_path):
    """``eval all --volume V`` ran Table I and the switch with V but the pace sweep with the trainer's default."""
    import types

    from services.experiments import pace, sections
    from services.experiments.report import QUICK

    asked = []

    def fake_interference(cfg, progress=None, compile=True):
        asked.append((cfg.protocol, cfg.volume))
        return types.SimpleNamespace(ratio=lambda: float("nan"))

    monkeypatch.setattr(pace, "run_interference", fake_interference)
    monkeypatch.setattr(pace, "_point", lambda res, prot, lib, p: point(p, 0.0, 0.0))
    pace.run_pace(PaceConfig(protocols=("product", "paper"), paces={"product": (0.25,), "paper": (0.05,)},
                             volume="spread"), progress=lambda _: None)
    assert asked == [("product", "spread"), ("paper", None)]  # the paper protocol keeps its own volume
    seen = []
    monkeypatch.setattr(sections, "run_pace", lambda cfg, say, compile: seen.append(cfg.volume) or PaceResult(cfg))
    sections.library_part("synthetic", "product:pace", QUICK, tmp_path, tmp_path / "models", volume="spread")
    assert seen == ["spread"]


def test_a_sweep_without_a_finite_positive_ratio_is_drawn(tmp_path):
    """A sweep of one pace where both planners scored 0 (ratio 0 / 0) ended in 'Data cannot be log-scaled'."""
    from services.experiments.pace import plot_pace

    nan = dataclasses.replace(point(0.1, 0.0, 0.0), ratio=float("nan"))
    zero = dataclasses.replace(point(0.2, 0.0, 0.0), ratio=0.0)
    for points in ([nan], [nan, zero], [nan, zero, dataclasses.replace(point(0.3, 0.0, 0.0), ratio=float("inf"))],
                   [nan, point(0.3, 1.0, 0.0)]):
        png = plot_pace(result(*points), tmp_path / f"pace{len(points)}.png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
