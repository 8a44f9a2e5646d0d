"""Strict JSON for everything the product prints or writes with ``--json``: no ``NaN`` or ``Infinity``.

Python's :func:`json.dumps` writes non-finite floats as the bare words ``NaN`` and ``Infinity``, which
``jq``, browsers and most other parsers refuse. A value that is not a finite number (a ratio over a zero
penetration, the statistics of a series without samples) is written as ``null`` instead; numpy scalars
and arrays become plain numbers and lists, paths become strings.
"""

from __future__ import annotations

import json
import math
from pathlib import PurePath
from typing import Any

import numpy as np

__all__ = ["dumps", "to_strict"]


def to_strict(obj: Any) -> Any:
    """A copy of ``obj`` that :func:`json.dumps` writes as strict JSON.

    Args:
        obj: Dicts, lists, tuples, numbers, strings, ``None``, numpy scalars or arrays and paths, nested.

    Returns:
        The same structure with non-finite floats as ``None``, numpy values as Python ones, tuples as
        lists and paths as strings.

    Raises:
        TypeError: Naming the first value of a type JSON cannot hold.
    """
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (str, bool, int)):
        return obj
    if isinstance(obj, dict):
        return {(k if isinstance(k, str) else str(k)): to_strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_strict(v) for v in obj]
    if isinstance(obj, (np.generic, np.ndarray)):
        return to_strict(obj.tolist())
    if isinstance(obj, PurePath):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__} ({obj!r:.60})")


def dumps(obj: Any, **kwargs: Any) -> str:
    """``json.dumps(to_strict(obj), allow_nan=False, **kwargs)``: strict JSON text of ``obj``."""
    return json.dumps(to_strict(obj), allow_nan=False, **kwargs)
