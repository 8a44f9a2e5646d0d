"""``foresight bench soak``'s summary: the reaction latency when the predictor grids only the newest pose."""

from __future__ import annotations

from types import SimpleNamespace as NS

import pytest

from tools.soak import _cover_latency


def test_reaction_latency_is_the_first_grid_for_the_pose_or_a_later_one():
    poses = [(0.0, NS(demo_id=1, index=0)), (0.1, NS(demo_id=1, index=1)), (0.2, NS(demo_id=1, index=2)),
             (0.3, NS(demo_id=2, index=0)), (0.4, NS(demo_id=1, index=3))]
    grids = [(0.25, NS(demo_id=1, index=2)),   # covers poses 0, 1, 2 of demo 1 (coalesced)
             (0.35, NS(demo_id=1, index=1)),   # an older index: covers nothing new
             (0.5, NS(demo_id=3, index=9))]    # another demonstration: covers nothing of demo 1 or 2
    lat = _cover_latency(poses, grids)
    assert lat == pytest.approx([0.25, 0.15, 0.05])  # demo 2's pose and index 3 are never covered
    assert _cover_latency(poses, []) == []
