"""How many graphs ``torch.compile`` keeps per function in a planning process: enough for every shape it plans.

Dynamo compiles one graph per input shape of a function and, past its recompile limit (8 by default) graphs of one
function, runs every new shape eagerly, with a warning. STOMP's steps are one function each for every planner of
the process (:func:`services.planner.stomp._compiled`) and the fused cost is one function for every
:class:`~services.planner.fused.FusedCost`: two shapes per goal count and waypoint count each, more with the cost's
batch sizes. A process that plans several of them (a report worker runs Table I at K = 1 and the switch at K = 2,
in both protocols' 40 and 101 waypoints) passed 8 part-way, and from there its shapes ran eagerly, which rounds
differently: the report's numbers then depended on which parts a worker had run before (two full reports of the
same code differed in their pace sweeps, 2026-11-27).

The limit is given to each ``torch.compile`` call (:func:`compile_every_shape`), not set in
``torch._dynamo.config``: since torch 2.13 that config is per thread (a ``ContextVar``), so a limit raised in the
thread that compiled first did not hold in the threads of later runs, which plan in threads of their own (the
lock-step harness starts each run's services as threads). Found by the next full report, whose log still said
``hit config.recompile_limit (8)`` for ``advance``.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import torch
import torch._dynamo.config as dynamo_config  # the documented knob (torch.compile's "recompilation" guide)

__all__ = ["RECOMPILE_LIMIT", "compile_every_shape"]

RECOMPILE_LIMIT = 64
"""Graphs kept per compiled function (dynamo's default: 8); a planning process sees far fewer shapes."""

_PER_CALL = "recompile_limit" in inspect.signature(torch.compile).parameters  # torch 2.13 has it


def compile_every_shape(fn: Callable[..., Any], **options: Any) -> Callable[..., Any]:
    """``torch.compile(fn, **options)`` keeping up to :data:`RECOMPILE_LIMIT` graphs of ``fn``, in every thread.

    Where this torch's ``torch.compile`` has no ``recompile_limit`` keyword, dynamo's config is raised instead
    (never lowered), which holds in the calling thread at least.
    """
    if _PER_CALL:
        return torch.compile(fn, recompile_limit=RECOMPILE_LIMIT, **options)
    dynamo_config.recompile_limit = max(int(dynamo_config.recompile_limit), RECOMPILE_LIMIT)
    return torch.compile(fn, **options)
