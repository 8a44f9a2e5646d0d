"""A planning process compiles every shape it plans (past dynamo's default of 8 graphs a function ran eagerly)."""

from __future__ import annotations

import torch
from torch._dynamo.utils import counters

from services.planner.compiling import RECOMPILE_LIMIT, allow_every_shape
from services.planner.stomp import _compiled


def _shifted(x: torch.Tensor) -> torch.Tensor:
    return x + 1.0


def test_more_shapes_than_dynamos_default_limit_are_all_compiled() -> None:
    """A report worker planned K = 1 and 2 at 40 and 101 waypoints: past 8 graphs its shapes ran eagerly, which
    rounds differently, so two reports of the same code differed where a worker had run other parts before."""
    _compiled("advance")  # what every compiled planner does first (and FusedCost with compile)
    assert torch._dynamo.config.recompile_limit >= RECOMPILE_LIMIT > 8
    allow_every_shape()  # never lowers it
    assert torch._dynamo.config.recompile_limit >= RECOMPILE_LIMIT
    fn = torch.compile(_shifted, backend="eager", dynamic=False)  # dynamo's graphs, without inductor's time
    before = counters["stats"]["unique_graphs"]
    for n in range(1, 13):  # 12 shapes: each its own graph, none run eagerly past the 8th
        fn(torch.zeros(n))
    assert counters["stats"]["unique_graphs"] - before == 12
