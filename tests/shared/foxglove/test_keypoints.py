"""A body tracker's keypoints in the scene: placed as the poses are, between reaches too, gone when the sensor stops."""

from __future__ import annotations

import numpy as np
import pytest

from shared.foxglove.keypoints import LIFETIME_S, RADIUS_M
from shared.foxglove.scene import SceneBuilder
from shared.foxglove.stream import SceneStream
from shared.human import HumanModel, place_in_scene
from shared.keypoints.fit import POINT_NAMES
from shared.protocol import HumanKeypoints, HumanPose

from .conftest import SCENE
from .test_scene import T, decoded

FEATURES = np.array([1.82, 1.71, 0.975, -2.4, 0.05, 0.02, 0.0, 0.4, 0.1, 0.3, 0.05, 0.6])  # the recorder's frame


def frame(features: np.ndarray, stamp: float = 10.0, lost: tuple[int, ...] = ()) -> HumanKeypoints:
    """The model's points of ``features`` as a sensor's frame in Foresight's point names (``lost``: NaN)."""
    pos = HumanModel().joint_positions(features)
    pos[list(lost)] = np.nan
    return HumanKeypoints(stamp=stamp, tick=-1, frame=int(stamp * 30), frame_id="recorder", names=list(POINT_NAMES),
                          positions=pos)


def test_before_any_reach_no_placement_is_known_and_nothing_is_drawn(builder) -> None:
    stream = SceneStream(SceneBuilder(SCENE, builder.robot, builder.human, builder.place))
    assert stream.due(frame(FEATURES)) == "/viz/keypoints"
    assert stream.draw(frame(FEATURES), T) == []


def test_keypoints_meet_the_body_of_the_poses_fitted_to_them_and_live_half_a_second(builder) -> None:
    """Placed by the newest demonstration's first pose, as the body is: the points of a posture land on the joints
    of that posture's body in the scene."""
    b = SceneBuilder(SCENE, builder.robot, builder.human, builder.place)
    stream = SceneStream(b)
    first = HumanPose(stamp=1.0, tick=-1, tick_last=True, demo_id=3, index=0, features=FEATURES)
    stream.due(first)  # every pose passes here: the first one is the placement's reference
    later = FEATURES + np.r_[0.1, -0.05, 0, 0.3, np.zeros(8)]  # the person has moved and turned since
    got = decoded(stream.draw(frame(later, lost=(POINT_NAMES.index("head"),)), T))["/viz/keypoints"]
    (entity,) = got.entities
    assert entity.id == "human/keypoints" and entity.frame_id == "world"
    assert entity.lifetime.ToNanoseconds() == round(LIFETIME_S * 1e9)  # gone when the sensor stops
    centres = np.array([[s.pose.position.x, s.pose.position.y, s.pose.position.z] for s in entity.spheres])
    want = HumanModel().joint_positions(place_in_scene(later, FEATURES, SCENE))
    want = np.delete(want, POINT_NAMES.index("head"), axis=0)  # a lost point is not drawn
    np.testing.assert_allclose(centres, want, atol=1e-6)
    assert all(s.size.x == pytest.approx(2 * RADIUS_M) for s in entity.spheres)
    assert np.linalg.norm(centres[POINT_NAMES.index("pelvis")] - SCENE.human.pelvis_xyz) > 0.05  # it moved


def test_keypoints_drawn_less_often_than_their_lifetime_live_two_drawing_periods(builder) -> None:
    """At --viz-rate-hz 1 the spheres lived 0.5 s of each second: they blinked."""
    for rate_hz, life_s in ((10.0, LIFETIME_S), (1.0, 2.0), (0.5, 4.0)):
        stream = SceneStream(SceneBuilder(SCENE, builder.robot, builder.human, builder.place), 1.0 / rate_hz)
        stream.due(HumanPose(stamp=1.0, tick=-1, tick_last=True, demo_id=3, index=0, features=FEATURES))
        (entity,) = decoded(stream.draw(frame(FEATURES), T))["/viz/keypoints"].entities
        assert entity.lifetime.ToNanoseconds() == round(life_s * 1e9), rate_hz


def test_keypoints_are_throttled_like_the_body(builder) -> None:
    stream = SceneStream(builder, viz_period_s=0.2)
    msg = frame(FEATURES, stamp=10.0)
    assert stream.due(msg) == "/viz/keypoints"
    stream.mark("/viz/keypoints", msg)
    assert stream.due(frame(FEATURES, stamp=10.1)) is None and stream.due(frame(FEATURES, stamp=10.2)) is not None
