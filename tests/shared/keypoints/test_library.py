"""Keypoint libraries: written from a motion library and fitted back (clean and noisy), CSV checks, layouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shared.human import HumanModel
from shared.keypoints import POINT_NAMES
from shared.keypoints.layouts import LAYOUTS, load_layout
from shared.keypoints.library import fit_keypoint_library, read_keypoint_csv, write_keypoint_library
from shared.library import MotionLibrary
from shared.synthetic import generate_library


@pytest.fixture(scope="module")
def small() -> MotionLibrary:
    lib = generate_library(2, 2, seed=4)
    return MotionLibrary(lib.class_names, lib.demos, [], lib.source)


def test_clean_round_trip_and_noisy_with_gaps(small, tmp_path: Path) -> None:
    model = HumanModel()
    write_keypoint_library(small, tmp_path / "clean")
    lib, report = fit_keypoint_library(tmp_path / "clean")
    assert lib.class_names == small.class_names and len(lib.demos) == len(small.demos)
    for got, want in zip(lib.demos, small.demos, strict=True):
        assert got.features.shape == want.features.shape
        err = np.linalg.norm(model.joint_positions(got.features) - model.joint_positions(want.features), axis=-1)
        assert np.median(err) < 1e-3
    assert np.median(report.residual_m) < 1e-3 and report.bridged == 0
    write_keypoint_library(small, tmp_path / "noisy", noise_m=0.02, drop=0.05, missing=0.1, seed=1)
    lib, report = fit_keypoint_library(tmp_path / "noisy")
    assert report.bridged > 0 and 0.01 < np.median(report.residual_m) < 0.05  # about the noise
    for got, want in zip(lib.demos, small.demos, strict=True):
        assert got.features.shape == want.features.shape  # dropped frames bridged: every frame is there
        err = np.linalg.norm(model.joint_positions(got.features) - model.joint_positions(want.features), axis=-1)
        assert np.median(err) < 0.03


def test_bad_csvs_are_named(tmp_path: Path) -> None:
    bad = tmp_path / "a.csv"
    bad.write_text("frame,demo,pelvis_x\n")
    with pytest.raises(ValueError, match="header must be demo,frame"):
        read_keypoint_csv(bad)
    bad.write_text("demo,frame,pelvis_x,pelvis_y,pelvis_z\n0,0,1,2,x\n")
    with pytest.raises(ValueError, match=r"a.csv:2: could not convert"):
        read_keypoint_csv(bad)
    bad.write_text("demo,frame,pelvis_x,pelvis_y,pelvis_z\n0,1,1,2,3\n0,1,1,2,3\n")
    with pytest.raises(ValueError, match="a.csv:3: frame 1 of demo 0 after frame 1"):
        read_keypoint_csv(bad)
    with pytest.raises(ValueError, match="no <class>.csv files"):
        fit_keypoint_library(tmp_path / "nothing")
    head = "demo,frame,pelvis_x,pelvis_y,pelvis_z,head_x,head_y,head_z"
    bad.write_text(f"{head}\n0,0,1,2,3,1,2,3\n1,0,1,2,3,1,2,3\n0,1,1,2,3,1,2,3\n")  # demo 0's rows split
    with pytest.raises(ValueError, match="a.csv:4: demo 0 again after demo 1"):
        read_keypoint_csv(bad)
    bad.write_text(f"{head}\n0,0,1,2,inf,1,2,3\n")
    with pytest.raises(ValueError, match="a.csv:2: a coordinate is infinite"):
        read_keypoint_csv(bad)
    bad.write_text("demo,frame,pelvis_x,pelvis_y,pelvis_z,pelvis_x,pelvis_y,pelvis_z\n0,0,1,2,3,4,5,6\n")
    with pytest.raises(ValueError, match="point.s. pelvis given twice"):  # the last stood for both
        read_keypoint_csv(bad)
    bad.write_text(f"\ufeff{head}\n0,0,1,2,3,1,2,3\n\n")  # a byte-order mark and a trailing blank line
    (demo,) = read_keypoint_csv(bad)
    assert demo.names == ["pelvis", "head"] and demo.positions.shape == (1, 2, 3)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "a.csv").write_text(f"{head}\n")
    with pytest.raises(ValueError, match="no demonstration in any of its 1 CSV files"):
        fit_keypoint_library(empty)


def test_a_point_the_layout_does_not_know_is_refused(small, tmp_path: Path) -> None:
    """A misspelt column was a point never observed: fitted without a word, 50 mm off at the median."""
    write_keypoint_library(small, tmp_path / "lib")
    first = sorted((tmp_path / "lib").glob("*.csv"))[0]
    text = first.read_text().replace("r_hand_", "rhand_")
    first.write_text(text)
    with pytest.raises(ValueError, match="point.s. rhand are not layout foresight's"):
        fit_keypoint_library(tmp_path / "lib")


def test_every_layout_loads_and_maps_its_points() -> None:
    for name in LAYOUTS:
        layout = load_layout(name)
        names = layout.source_names
        pos = np.arange(len(names) * 3, dtype=float).reshape(1, len(names), 3)
        mapped = layout.to_model(names, pos)
        given = [p for p in POINT_NAMES if p in layout.points]
        assert np.all(np.isfinite(mapped[0, [POINT_NAMES.index(p) for p in given]]))
        assert np.all(np.isnan(np.delete(mapped[0], [POINT_NAMES.index(p) for p in given], axis=0)))
    coco = load_layout("coco17")
    pelvis = coco.to_model(["left_hip", "right_hip"], np.array([[0.0, 0.1, 1.0], [0.0, -0.1, 1.0]]))
    np.testing.assert_allclose(pelvis[POINT_NAMES.index("pelvis")], [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="unknown"):
        load_layout("kinect_v1")


def test_a_layout_knows_every_point_its_sensor_sends() -> None:
    coco = load_layout("coco17")
    every_coco_point = ["nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
                        "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip",
                        "left_knee", "right_knee", "left_ankle", "right_ankle"]
    assert coco.unknown(every_coco_point) == []
    assert coco.unknown(["right_wrist", "r_wrist", "RWRA"]) == ["r_wrist", "RWRA"]  # another layout's names
    assert set(coco.ignored).isdisjoint(coco.source_names)
    gait = load_layout("plugin_gait")
    assert set(gait.ignored).isdisjoint(gait.source_names) and gait.unknown(["C7", "RFIN", "LKNE"]) == []
    assert load_layout("foresight").unknown(["pelvis", "left_hip"]) == ["left_hip"]
