"""How many graphs ``torch.compile`` keeps per function in a planning process: enough for every shape it plans.

Dynamo compiles one graph per input shape of a function and, past ``torch._dynamo.config.recompile_limit``
(8 by default) graphs of one function, runs every new shape eagerly, with a warning. STOMP's steps are one
function each for every planner of the process (:func:`services.planner.stomp._compiled`) and the fused cost is
one function for every :class:`~services.planner.fused.FusedCost`: two shapes per goal count and waypoint count
each, more with the cost's batch sizes. A process that plans several of them (a report worker runs Table I
at K = 1 and the switch at K = 2, in both protocols' 40 and 101 waypoints) passed 8 part-way, and from there its
shapes ran eagerly, which rounds differently: the report's numbers then depended on which parts a worker had run
before (two full reports of the same code differed in their pace sweeps, 2026-11-27). With room for every shape
each is compiled, whatever ran before.
"""

from __future__ import annotations

import torch._dynamo.config as dynamo_config  # the documented knob (torch.compile's "recompilation" guide)

__all__ = ["RECOMPILE_LIMIT", "allow_every_shape"]

RECOMPILE_LIMIT = 64
"""Graphs kept per compiled function (dynamo's default: 8); a planning process sees far fewer shapes."""


def allow_every_shape() -> None:
    """Raise dynamo's per-function graph limit of this process to :data:`RECOMPILE_LIMIT` (never lowers it)."""
    dynamo_config.recompile_limit = max(int(dynamo_config.recompile_limit), RECOMPILE_LIMIT)
