"""How the report's work is split into parts and ordered for the worker processes."""

from __future__ import annotations

import pytest

from services.experiments.report import FULL, QUICK
from services.experiments.sections import PROTOCOL_PARTS, part_names, part_weight


def test_part_names_are_recognition_then_each_protocols_three_parts() -> None:
    assert part_names(("product",)) == ["recognition", "product:table1", "product:switch", "product:pace"]
    names = part_names(("product", "paper"))
    assert len(names) == 1 + 2 * len(PROTOCOL_PARTS) and len(set(names)) == len(names)


def test_part_weight_counts_planned_goal_steps_longest_first() -> None:
    # FULL: Table I 5 demonstrations x 10 seeds x 2 planners + basic STOMP on the 5 at seed 0 and once per later
    # seed (services.experiments.reuse); the switch 25 x 2 planners x 2 goals, x 2 for its
    # possible mirrored run; the pace sweep 5 paces x 3 x 1 x 2 planners; the paper protocol's steps 1.6x
    assert part_weight("product:table1", FULL) == 100 + 5 + 9
    assert part_weight("product:switch", FULL) == 200
    assert part_weight("product:pace", FULL) == 30
    assert part_weight("paper:table1", FULL) == 114 * 1.6
    assert part_weight("recognition", FULL) == 0  # plans nothing: last
    order = sorted(part_names(("product", "paper")), key=lambda part: -part_weight(part, FULL))
    assert order == ["paper:switch", "product:switch", "paper:table1", "product:table1", "paper:pace",
                     "product:pace", "recognition"]
    assert part_weight("product:pace", QUICK) == 1 * 1 * 1 * 2  # --quick: one pace per protocol


def test_recognition_is_compared_with_the_paper_where_the_paper_read_it() -> None:
    """The paper's 50 % at 43 % executed was compared with the rate at 40 %, the nearest grid point."""
    import types

    from services.experiments.sections import _between, _rate_at

    res = types.SimpleNamespace(fractions=[0.2, 0.4, 0.5, 0.6], rates=[0.1, 0.4, 0.7, 0.8])
    assert _rate_at(res, 0.43) == pytest.approx(0.49) and _rate_at(res, 0.6) == 0.8
    assert _between(res.fractions, 0.43) == " (interpolated, 40%-50%)" and _between(res.fractions, 0.6) == ""
    assert _rate_at(res, 1.0) == 0.8 and _between(res.fractions, 1.0) == " (the nearest measured)"
