"""The plot-able messages of a run: the class posterior and the planner's costs, one JSON object per message.

Foxglove's Plot panel draws any numeric field by its message path, e.g. ``/viz/posterior.probability.red_cup``
or ``/viz/costs.total.blue_cup``; class and goal names are the keys, so a path reads as what it plots. A
cost that is not finite (an invalid candidate) is ``null``: JSON has no infinity, and a gap is what a plot
should show.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from shared.belief import recognised_class
from shared.protocol import ClassPosterior, Plan

__all__ = ["POSTERIOR_SCHEMA", "COSTS_SCHEMA", "posterior_chart", "costs_chart"]

_TIME = {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0},
                                          "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}


def _by_name(what: str) -> dict[str, Any]:
    return {"type": "object", "description": what, "additionalProperties": {"type": ["number", "null"]}}


POSTERIOR_SCHEMA: dict[str, Any] = {
    "title": "foresight.viz.Posterior",
    "description": "The predictor's class posterior p(c|xi) after a pose (plot /viz/posterior.probability.<class>)",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "demo_id": {"type": "integer"},
        "index": {"type": "integer", "description": "the pose's sample index in its demonstration"},
        "probability": _by_name("p(c|xi) per class name"),
        "recognised": {"type": "string", "description": "the most probable class; empty when the posterior is flat "
                       "(its top class under 2/K and under 1/2: no class recognised)"},
        "recognised_probability": {"type": "number", "description": "the most probable class's probability"},
        "familiar": {"type": "boolean", "description": "whether any class explains the motion's last frames (if "
                     "not, 'recognised' is only the least unlikely class)"},
        "familiarity": {"type": "number", "description": "nats per frame; below the model's novelty threshold: "
                        "unfamiliar"},
    },
}

COSTS_SCHEMA: dict[str, Any] = {
    "title": "foresight.viz.Costs",
    "description": "A plan's costs per goal (plot /viz/costs.total.<goal>); null: not finite",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "step": {"type": "integer"},
        "chosen": {"type": "string", "description": "the goal the robot follows"},
        "planning_ms": {"type": "number"},
        "total": _by_name("total cost per goal"),
        "human": _by_name("penetration of the predicted occupancy per goal"),
        "obstacle": _by_name("obstacle cost per goal"),
        "smoothness": _by_name("smoothness cost per goal"),
    },
}


def _time(seconds: float) -> dict[str, int]:
    ns = max(0, int(round(seconds * 1e9)))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _named(names: list[str], values: np.ndarray) -> dict[str, float | None]:
    return {n: (float(v) if math.isfinite(float(v)) else None) for n, v in zip(names, values, strict=True)}


def posterior_chart(post: ClassPosterior, stamp: float) -> dict[str, Any]:
    """The ``/viz/posterior`` object of ``post``, stamped ``stamp`` (seconds); ``recognised`` is empty when flat."""
    k = int(np.argmax(post.posterior))
    return {"timestamp": _time(stamp), "demo_id": int(post.demo_id), "index": int(post.index),
            "probability": _named(list(post.class_names), post.posterior),
            "recognised": recognised_class(post.class_names, post.posterior),
            "recognised_probability": float(post.posterior[k]),
            "familiar": bool(post.familiar), "familiarity": float(post.familiarity)}


def costs_chart(plan: Plan, stamp: float) -> dict[str, Any]:
    """The ``/viz/costs`` object of ``plan``, stamped ``stamp`` (seconds)."""
    names = list(plan.goal_names)
    return {"timestamp": _time(stamp), "step": int(plan.step),
            "chosen": names[plan.chosen] if 0 <= plan.chosen < len(names) else "",
            "planning_ms": float(plan.planning_ms), "total": _named(names, plan.cost_total),
            "human": _named(names, plan.cost_human), "obstacle": _named(names, plan.cost_obstacle),
            "smoothness": _named(names, plan.cost_smoothness)}
