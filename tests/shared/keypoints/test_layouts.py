"""Skeleton layouts: a Foresight point described in the sensor's names."""

from __future__ import annotations

import numpy as np
import pytest

from shared.keypoints.fit import POINT_NAMES
from shared.keypoints.layouts import load_layout


def test_a_point_made_of_other_names_is_described_with_them_and_those_not_seen() -> None:
    coco = load_layout("coco17")
    assert coco.describe("pelvis") == "pelvis (left_hip, right_hip)"
    assert coco.describe("pelvis", seen={"right_hip"}) == "pelvis (left_hip, right_hip: left_hip not seen)"
    assert coco.describe("pelvis", seen={"left_hip", "right_hip"}) == "pelvis (left_hip, right_hip)"


def test_a_point_the_sensor_names_as_foresight_does_is_its_name_alone() -> None:
    assert load_layout("foresight").describe("r_wrist", seen=set()) == "r_wrist"
    assert load_layout("coco17").describe("not_a_point") == "not_a_point"


@pytest.mark.parametrize(("layout", "right", "left"), [("coco17", "right_{}", "left_{}"),
                                                        ("mediapipe33", "right_{}", "left_{}"),
                                                        ("body25", "R{}", "L{}")])
def test_the_sensors_right_points_are_the_models_right_joints(layout: str, right: str, left: str) -> None:
    """The reach rule watches the model's right wrist: a layout mapping a sensor's right side to the model's left would
    have tracked the other hand (pinned before only by both sides mapping somewhere)."""
    lay = load_layout(layout)
    parts = ("shoulder", "elbow", "wrist") if layout != "body25" else ("Shoulder", "Elbow", "Wrist")
    names = [side.format(p) for p in parts for side in (right, left)]
    pos = np.arange(len(names) * 3, dtype=float).reshape(len(names), 3)  # each point its own place
    model = lay.to_model(names, pos)
    for i, joint in enumerate(("shoulder", "elbow", "wrist")):
        np.testing.assert_array_equal(model[POINT_NAMES.index(f"r_{joint}")], pos[names.index(right.format(parts[i]))])
        np.testing.assert_array_equal(model[POINT_NAMES.index(f"l_{joint}")], pos[names.index(left.format(parts[i]))])
