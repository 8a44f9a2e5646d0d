"""JSON text of a large object, encoded a slice at a time so that other threads can run in between.

The executor's Foxglove thread encodes updates of ~0.6 MB (an occupancy's cubes) while its Zenoh
callback must take every plan as it arrives; one ``json.dumps`` call holds the GIL throughout.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["dumps_sliced"]

_SLICE = 200
"""Items of a long JSON list encoded per ``json.dumps`` call by :func:`dumps_sliced`."""


def dumps_sliced(obj: Any) -> str:
    """``json.dumps(obj, separators=(",", ":"))``, the same text, with long lists encoded a slice at a time.

    One ``json.dumps`` call holds the GIL throughout: an occupancy's ~3000 cubes took 12-15 ms, during
    which the thread that receives the plans could not run; between two slices (~1 ms each) it can.
    Dicts with string keys and lists of up to 8 items are walked (the few top levels of a Foxglove
    update); a longer list is encoded whole, or in slices beyond ``_SLICE`` items.
    """
    if isinstance(obj, dict) and all(isinstance(k, str) for k in obj):
        return "{" + ",".join(_plain(k) + ":" + dumps_sliced(v) for k, v in obj.items()) + "}"
    if isinstance(obj, list) and len(obj) <= 8:
        return "[" + ",".join(dumps_sliced(v) for v in obj) + "]"
    if isinstance(obj, list) and len(obj) > _SLICE:
        return "[" + ",".join(_plain(obj[i:i + _SLICE])[1:-1] for i in range(0, len(obj), _SLICE)) + "]"
    return _plain(obj)


def _plain(obj: Any) -> str:
    return json.dumps(obj, separators=(",", ":"))
