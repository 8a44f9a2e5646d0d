"""A frame's plausibility in words: the torso's lean, optional points far off the fit, missing points named with the
sensor's own, the point furthest from a refused fit."""

from __future__ import annotations

import numpy as np
import pytest

from services.tracker.checks import MAX_TILT_DEG, UPRIGHT_CONFIRM, torso_tilt_deg
from services.tracker.core import TrackerConfig, TrackerCore
from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES
from shared.keypoints.layouts import load_layout
from shared.protocol import DemoMarker, HumanPose

MODEL = HumanModel()
NAMES = list(POINT_NAMES)
RATE = 30.0


@pytest.fixture(scope="module")
def joints(reach) -> np.ndarray:
    """``(T, J, 3)``: the model's points along the reach (conftest)."""
    return MODEL.joint_positions(reach)


@pytest.mark.parametrize("frame", ["camera (z forward)", "y up"])
def test_keypoints_whose_up_is_not_z_are_refused_as_not_upright(joints, frame: str) -> None:
    """Before, every frame was taken, and a reach of a person lying on their side went to the predictor."""
    rotate = {"camera (z forward)": np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]),
              "y up": np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])}[frame]
    core = TrackerCore()
    outs = [core.on_frame(i / RATE, NAMES, p @ rotate + [0, 0, 1.0]) for i, p in enumerate(joints)]
    assert core.accepted == 0 and core.refused["upright"] == len(joints)
    assert outs[0].refused.startswith("upright: the torso (pelvis to the shoulders' midpoint) leans ")
    assert f"from the vertical (z), more than {MAX_TILT_DEG:g}, and the track has not stood upright" in outs[0].refused
    assert "is z the keypoints' up?" in outs[0].refused
    assert not any(o.messages for o in outs)


def test_a_person_bending_over_once_tracked_upright_is_taken() -> None:
    """Judged frame by frame, a bend beyond 60 deg was refused as keypoints whose up is not z (46 of 120 frames here),
    and the gap ended the reach under way."""
    from shared.feature_sets import HERAKLES_NAMES

    f = np.zeros(12)
    f[HERAKLES_NAMES.index("pelvis_z")] = 1.0
    lean = np.radians(110) * np.sin(np.linspace(0, np.pi, 120)) ** 2  # upright, bent (torso_y 110 deg), upright
    frames = []
    for a in np.concatenate([np.zeros(UPRIGHT_CONFIRM), lean]):
        g = f.copy()
        g[HERAKLES_NAMES.index("torso_y")] = a
        frames.append(MODEL.joint_positions(g))
    core = TrackerCore()
    outs = [core.on_frame(i / RATE, NAMES, p) for i, p in enumerate(frames)]
    assert max(torso_tilt_deg(p) for p in frames) > MAX_TILT_DEG + 10  # 75 deg at the bend's deepest
    assert sum(core.refused.values()) == 0 and core.accepted == len(frames), [o.refused for o in outs if o.refused]
    core = TrackerCore()  # bent from its first frame: refused until it has stood upright long enough
    outs = [core.on_frame(i / RATE, NAMES, p) for i, p in enumerate(frames[UPRIGHT_CONFIRM + 55:])]
    assert outs[0].refused.startswith("upright: ")
    assert "has not stood upright for 15 frames (0 so far)" in outs[0].refused
    assert core.accepted > 0 and core.refused["upright"] > 0


def test_an_optional_point_reported_at_the_origin_is_left_out_and_the_reach_goes_on(joints) -> None:
    """Sensors report a point they did not detect at (0, 0, 0). Before, the head there for 20 frames refused them all
    (residual 77 cm), the track was lost and the reach gave no pose at all."""
    head = NAMES.index("head")

    def poses(core: TrackerCore, spoil: bool) -> list:
        out = []
        for i, p in enumerate(joints):
            p = p.copy()
            if spoil and 60 <= i < 80:
                p[head] = 0.0
            out += core.on_frame(i / RATE, NAMES, p).messages
        return out

    clean, core = poses(TrackerCore(), False), TrackerCore()
    spoilt = poses(core, True)
    assert sum(core.refused.values()) == 0 and core.points_left_out == 20
    assert [type(m) for m in spoilt] == [type(m) for m in clean]  # the same markers and as many poses
    got = np.array([m.features for m in spoilt if isinstance(m, HumanPose)])
    want = np.array([m.features for m in clean if isinstance(m, HumanPose)])
    assert np.abs(got - want).max() < 0.05 and sum(isinstance(m, DemoMarker) for m in spoilt) == 4  # at rest, reach


def test_a_required_point_far_off_is_still_refused_naming_the_furthest_point(joints) -> None:
    wild = joints[0].copy()
    wild[NAMES.index("r_wrist")] += [0.0, 0.0, 1.0]
    out = TrackerCore().on_frame(0.0, NAMES, wild)
    assert out.refused.startswith("residual: fit residual ") and "; furthest: r_wrist " in out.refused
    coco = load_layout("coco17")
    names = [n for point in NAMES for n in coco.points.get(point, ())]
    positions = np.array([joints[0][NAMES.index(point)] for point in NAMES for _ in coco.points.get(point, ())])
    positions[names.index("right_wrist")] += [0.0, 0.0, 1.0]
    out = TrackerCore(TrackerConfig(layout="coco17")).on_frame(0.0, names, positions)
    assert "; furthest: r_wrist (right_wrist) " in out.refused and " cm off" in out.refused


def test_a_missing_point_is_named_with_the_sensors_points_it_is_made_of(joints) -> None:
    """Before: 'required point(s) missing: pelvis', a point the user's COCO sensor never sends."""
    coco = load_layout("coco17")
    names = [n for point in NAMES for n in coco.points.get(point, ())]
    positions = np.array([joints[0][NAMES.index(point)] for point in NAMES for _ in coco.points.get(point, ())])
    positions[names.index("left_hip")] = np.nan
    out = TrackerCore(TrackerConfig(layout="coco17")).on_frame(0.0, names, positions)
    assert out.refused == "missing: required point(s) missing: pelvis (left_hip, right_hip: left_hip not seen)"
    positions = joints[0].copy()
    positions[NAMES.index("r_wrist")] = np.nan
    assert TrackerCore().on_frame(0.0, NAMES, positions).refused == "missing: required point(s) missing: r_wrist"
