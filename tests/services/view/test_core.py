"""ViewCore: the live scene is the recorded one (same stream, same messages), throttled, and counted."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from services.view.config import ViewConfig
from services.view.core import ViewCore
from shared.config import ConfigError
from shared.foxglove.scene import default_builder
from shared.foxglove.stream import SceneStream
from shared.protocol import OccupancyGrid
from shared.scene import load_scene

SCENE = load_scene(None)


@pytest.fixture(scope="module")
def builder():
    return default_builder(SCENE)


def grid(stamp: float) -> OccupancyGrid:
    dense = np.zeros(SCENE.grid.dims, np.float32)
    dense[18:24, 12:20, 15:22] = 0.8
    return OccupancyGrid.from_dense(dense, SCENE.grid.origin, SCENE.grid.resolution, stamp=stamp, tick=0,
                                    tick_last=True, demo_id=0, index=0, method="prediction")


def test_the_live_scene_is_what_the_log_records(builder) -> None:
    clock = itertools.count(1_000, 1_000).__next__
    core = ViewCore(builder, viz_period_s=0.5, clock=clock)
    live = core.on_message(grid(0.0))
    recorded = SceneStream(builder, 0.5).draw(grid(0.0), live[0].log_time)
    assert [(m.topic, m.data, m.log_time) for m in live] == [(m.topic, m.data, m.log_time) for m in recorded]
    assert core.on_message(grid(0.2)) == []  # too soon
    assert len(core.on_message(grid(0.5))) == 1
    assert core.drawn == {"/viz/occupancy": 2}
    assert [m.topic for m in core.static()] == ["/viz/scene", "/tf"]


def test_a_message_nobody_watches_is_not_drawn_and_not_counted_as_drawn(builder) -> None:
    """The view drew every message (the robot's FK, the encoding) though no client subscribed."""
    core = ViewCore(builder, viz_period_s=0.5, clock=itertools.count(1_000, 1_000).__next__)
    watching: set[str] = set()
    assert core.on_message(grid(0.0), watching.__contains__) == [] and core.drawn == {}
    watching.add("/viz/occupancy")
    assert len(core.on_message(grid(0.1), watching.__contains__)) == 1  # not held back by the one not drawn
    assert core.drawn == {"/viz/occupancy": 1}


def test_bad_options_are_named() -> None:
    for kwargs, name in (({"port": 70000}, "view.port"), ({"viz_rate_hz": 0}, "view.viz_rate_hz"),
                         ({"nice": 25}, "view.nice"), ({"device": ""}, "view.device"),
                         ({"device": "gpu"}, "view.device")):
        with pytest.raises(ConfigError, match=name):
            ViewConfig(**kwargs).validate()
