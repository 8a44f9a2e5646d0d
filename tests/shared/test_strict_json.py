"""strict_json: what the product prints with --json parses in strict parsers (no NaN, no Infinity)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from shared import strict_json


def _strict(text: str) -> object:
    def refuse(word: str) -> None:
        raise ValueError(f"not strict JSON: {word}")
    return json.loads(text, parse_constant=refuse)


def test_non_finite_numbers_become_null_and_the_rest_is_kept() -> None:
    data = {"ratio": math.inf, "p99": float("nan"), "low": -math.inf, "n": 3, "x": 0.25, "ok": True, "s": "a",
            "none": None, "nested": [{"v": np.float32("nan"), "w": np.float64(1.5)}, (1, math.inf)],
            "array": np.array([1.0, np.nan, 2.0]), "count": np.int64(7), "path": Path("runs/demo"), 4: "key"}
    got = _strict(strict_json.dumps(data))
    assert got == {"ratio": None, "p99": None, "low": None, "n": 3, "x": 0.25, "ok": True, "s": "a", "none": None,
                   "nested": [{"v": None, "w": 1.5}, [1, None]], "array": [1.0, None, 2.0], "count": 7,
                   "path": "runs/demo", "4": "key"}
    with pytest.raises(ValueError, match="Infinity"):  # what the standard library writes instead
        _strict(json.dumps({"ratio": math.inf}))


def test_a_value_json_cannot_hold_is_named() -> None:
    with pytest.raises(TypeError, match="not JSON serialisable: set"):
        strict_json.dumps({"a": {1, 2}})


def test_keyword_arguments_pass_through() -> None:
    assert strict_json.dumps({"b": 1, "a": float("nan")}, sort_keys=True, indent=1) == '{\n "a": null,\n "b": 1\n}'
