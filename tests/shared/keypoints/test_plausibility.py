"""Keypoints a person in the library's frame can have: metres, z up; batched equals looped."""

from __future__ import annotations

import numpy as np
import pytest

from shared.human import HumanModel
from shared.keypoints.fit import POINT_NAMES
from shared.keypoints.plausibility import MAX_TILT_DEG, torso_tilt_deg, units_problem
from shared.synthetic import generate_library

CAMERA = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # (x, y, z) -> (x, -z, y): z forward, y down (OpenCV)


@pytest.fixture(scope="module")
def joints() -> np.ndarray:
    """``(D, T, J, 3)``: the model's points of four synthetic demonstrations."""
    lib = generate_library(2, 2, seed=4)
    return np.stack([HumanModel().joint_positions(d.features) for d in lib.demos])


def test_the_library_stands_upright_and_a_frame_on_its_side_does_not(joints) -> None:
    assert np.nanmax(torso_tilt_deg(joints)) < MAX_TILT_DEG / 2
    assert torso_tilt_deg(joints[0, 0] @ CAMERA) == pytest.approx(90, abs=5)
    wild = joints[0, 0].copy()
    wild[POINT_NAMES.index("pelvis")] += [0, 0, 0.4]  # one point wild, the torso too short to judge: the fit refuses it
    assert np.isnan(torso_tilt_deg(wild))
    missing = joints[0, 0].copy()
    missing[POINT_NAMES.index("l_shoulder")] = np.nan
    assert np.isnan(torso_tilt_deg(missing))


def test_batched_tilt_equals_looped(joints) -> None:
    batched = torso_tilt_deg(joints)
    looped = np.array([[torso_tilt_deg(frame) for frame in demo] for demo in joints])
    assert batched.shape == joints.shape[:2]
    np.testing.assert_allclose(batched, looped)


def test_coordinates_beyond_the_wire_limit_read_as_millimetres(joints) -> None:
    names = list(POINT_NAMES)
    assert units_problem(names, joints[0]) == ""
    lost = joints[0].copy()
    lost[3, 2] = np.nan  # a lost point is no coordinate
    assert units_problem(names, lost) == ""
    glitch = joints[0].copy()
    glitch[7, POINT_NAMES.index("l_hand"), 0] = 25.0  # one frame's glitch: the wire or the fit refuses that frame
    assert units_problem(names, glitch) == ""  # (the whole recording was refused for it)
    mm = joints[0] * 1000.0
    problem = units_problem(names, mm)
    assert problem.startswith(f"coordinates beyond 20 m of the origin in {len(mm)} of its {len(mm)} frames (up to ")
    assert problem.endswith("keypoints are in metres (millimetres? divide by 1000)")
    far = int(np.unravel_index(int(np.argmax(np.abs(mm))), mm.shape)[1])
    assert f"m, '{names[far]}')" in problem
