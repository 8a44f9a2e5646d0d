"""Skeleton layouts: a Foresight point described in the sensor's names."""

from __future__ import annotations

from pathlib import Path

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


def test_each_layout_reads_a_sensors_points_in_that_sensors_own_order() -> None:
    """A ROS 2 PoseArray is read in the layout's native order unless --ros2-points says otherwise: the default was the
    table's dozen names, an order no driver sends (a COCO driver's every sample was refused on its count)."""
    coco = load_layout("coco17").native_order
    assert len(coco) == 17 and coco[:5] == ["nose", "left_eye", "right_eye", "left_ear", "right_ear"]
    assert coco[9:13] == ["left_wrist", "right_wrist", "left_hip", "right_hip"]  # COCO's ids 9..12
    mediapipe = load_layout("mediapipe33").native_order
    assert len(mediapipe) == 33 and mediapipe[11:17] == ["left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
                                                         "left_wrist", "right_wrist"]  # PoseLandmark 11..16
    assert mediapipe[23:25] == ["left_hip", "right_hip"] and mediapipe[-1] == "right_foot_index"
    body25 = load_layout("body25").native_order
    assert len(body25) == 25 and body25[:9] == ["Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder",
                                                 "LElbow", "LWrist", "MidHip"]
    assert load_layout("foresight").native_order == list(POINT_NAMES)
    gait = load_layout("plugin_gait")  # markers have no standard order: the table's
    assert gait.order == () and gait.native_order == gait.table_names
    for name in ("coco17", "mediapipe33", "body25"):
        lay = load_layout(name)
        assert sorted(lay.native_order) == sorted({*lay.source_names, *lay.ignored})  # each point once


def test_a_layout_whose_order_leaves_out_or_repeats_a_point_is_refused(tmp_path, monkeypatch) -> None:
    from shared.keypoints import layouts

    table = tmp_path / "data" / "keypoints" / "coco17.toml"
    table.parent.mkdir(parents=True)
    shipped = (Path(layouts.__file__).parents[1] / "data" / "keypoints" / "coco17.toml").read_text()
    monkeypatch.setattr(layouts.resources, "files", lambda package: tmp_path)
    table.write_text(shipped.replace('order = ["nose", "left_eye", ', 'order = ["nose", "nose", '))
    with pytest.raises(ValueError, match=r"^keypoint layout coco17: order must list each of its points once "
                                         r"\(missing \['left_eye'\]; given twice \['nose'\]\)$"):
        load_layout("coco17")
    table.write_text(shipped.replace('order = ["nose", ', 'order = ["snout", '))
    with pytest.raises(ValueError, match=r"\(missing \['nose'\]; not its points \['snout'\]\)$"):
        load_layout("coco17")
