"""Skeleton layouts: a Foresight point described in the sensor's names."""

from __future__ import annotations

from shared.keypoints.layouts import load_layout


def test_a_point_made_of_other_names_is_described_with_them_and_those_not_seen() -> None:
    coco = load_layout("coco17")
    assert coco.describe("pelvis") == "pelvis (left_hip, right_hip)"
    assert coco.describe("pelvis", seen={"right_hip"}) == "pelvis (left_hip, right_hip: left_hip not seen)"
    assert coco.describe("pelvis", seen={"left_hip", "right_hip"}) == "pelvis (left_hip, right_hip)"


def test_a_point_the_sensor_names_as_foresight_does_is_its_name_alone() -> None:
    assert load_layout("foresight").describe("r_wrist", seen=set()) == "r_wrist"
    assert load_layout("coco17").describe("not_a_point") == "not_a_point"
