"""dumps_sliced: the text of json.dumps, long lists encoded a slice at a time."""

from __future__ import annotations

import json

from shared.recording.json_slices import dumps_sliced


def test_sliced_json_is_json_dumps() -> None:
    """The writer encodes long lists a slice at a time (the GIL is free between slices): the same text."""
    cubes = [{"pose": {"position": {"x": i * 0.1, "y": -i, "z": 0.5}}, "color": {"r": 1, "a": 0.5}}
             for i in range(1234)]
    for obj in ({"entities": [{"id": "occupancy", "cubes": cubes, "lines": []}], "deletions": []}, cubes[:7],
                {"a": [1, 2, {"b": list(range(1000))}], "c": None, "d": "\u00e9\n"}, {1: "x", "y": [True]}, [], {},
                [[1] * 500], "text", 3.5):
        assert dumps_sliced(obj) == json.dumps(obj, separators=(",", ":"))
