"""Foxglove's value messages built from numbers."""

from __future__ import annotations

import numpy as np
import pytest
from foxglove.messages import SceneEntity, SceneUpdate

from shared.foxglove.decode import SchemaDecoder
from shared.foxglove.primitives import duration, spheres, timestamp


def read_back(prims) -> list:
    """The spheres as a reader sees them: encoded in a SceneUpdate by the SDK, decoded from its schema."""
    schema = SceneUpdate.get_schema()
    msg = SceneUpdate(entities=[SceneEntity(id="s", frame_id="world", spheres=prims)])
    return SchemaDecoder().decode("/s", schema.name, schema.encoding, schema.data, msg.encode()).entities[0].spheres


def test_times_round_to_the_nanosecond_and_carry_into_seconds() -> None:
    assert timestamp(1.9999999996) == timestamp(2.0) != timestamp(1.999999999)
    assert duration(0.5) == duration(0.5000000001) != duration(0.500000001)
    assert timestamp(-3.0) == timestamp(0.0) and duration(-1.0) == duration(0.0)


def test_one_radius_serves_every_sphere_and_a_list_gives_each_its_own() -> None:
    centers = np.array([[0.0, 0.1, 0.2], [1.0, 1.1, 1.2]])
    same = read_back(spheres(centers, 0.03, (1.0, 0.5, 0.0, 0.9)))
    assert [s.size.x for s in same] == [pytest.approx(0.06)] * 2
    assert [(s.pose.position.x, s.pose.position.z) for s in same] == [(0.0, 0.2), (1.0, 1.2)]
    assert same[1].color.g == 0.5 and same[1].pose.orientation.w == 1.0
    own = read_back(spheres(centers, [0.01, 0.02], (1.0, 1.0, 1.0, 1.0)))
    assert [s.size.z for s in own] == [pytest.approx(0.02), pytest.approx(0.04)]


def test_radii_that_do_not_match_the_centres_are_refused() -> None:
    with pytest.raises(ValueError):
        spheres(np.zeros((3, 3)), [0.1, 0.2], (1.0, 1.0, 1.0, 1.0))
