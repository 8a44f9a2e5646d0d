"""The paper protocol's settings, the authors' trials and Move3D's path weights."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.experiments.authors import FIG9_TRACES, TABLE1_RUNS, table1_summary
from services.experiments.protocol import (
    AUTHORS_DIGESTS,
    PAPER,
    PRODUCT,
    authors_trial,
    move3d_path_weights,
    protocol,
    trial_digest,
)
from services.planner.stomp import finite_difference_matrix
from shared.library import MotionLibrary, load_library, save_library, write_csv_dir
from shared.robot import PR2
from shared.runtime import UserError
from shared.scene import load_scene
from shared.synthetic import generate_library


def test_protocols_by_name_and_the_authors_paces():
    assert protocol("paper") is PAPER and protocol("product") is PRODUCT
    with pytest.raises(ValueError, match="protocol"):
        protocol("papr")
    assert PAPER.pace("pr2_two_cups_side_parallel") == pytest.approx(0.05)  # 10 x 0.005
    assert PAPER.pace("pr2_two_cups_facing") == pytest.approx(0.085)  # 17 x 0.005
    assert PRODUCT.pace("pr2_two_cups_side") == 0.0


def test_the_noise_is_the_authors_0_002_times_r_inverse():
    # 101 waypoints (100 segments), 99 free; the product's 3-point stencil gives the same R^-1 maximum within 1 %
    a = finite_difference_matrix(PAPER.waypoints - 2)
    r_inv_max = float(np.linalg.inv((a.T @ a).numpy()).max())
    assert PAPER.noise_std == pytest.approx(0.002 * math.sqrt(r_inv_max), rel=0.01)


@pytest.fixture(scope="module")
def compound_library(tmp_path_factory) -> MotionLibrary:
    """A generated library as CSV files: classes compound_0 .. compound_7, as the paper's, of other motions."""
    out = tmp_path_factory.mktemp("generated")
    write_csv_dir(generate_library(8, 5, seed=0), out)
    return load_library(out, report=False)


def test_authors_trials_on_the_paper_library_only(compound_library, monkeypatch):
    theirs = {t: trial_digest(compound_library, t) for t in AUTHORS_DIGESTS}  # this library taken for the paper's
    monkeypatch.setattr("services.experiments.protocol.AUTHORS_DIGESTS", theirs)
    lib = compound_library
    assert authors_trial("auto", PAPER, "pr2_two_cups_side_parallel", lib) == ("compound_1", (0, 1, 2, 3, 4))
    assert authors_trial("auto", PAPER, "pr2_two_cups_facing", lib) == ("compound_3", (2,))
    assert authors_trial("auto", PRODUCT, "pr2_two_cups_facing", lib) is None
    synthetic = generate_library(8, 5, seed=0)
    assert authors_trial("auto", PAPER, "pr2_two_cups_facing", synthetic) is None
    assert authors_trial("cup", PAPER, "pr2_two_cups_facing", lib) is None
    with pytest.raises(UserError, match="authors ran no trial in scene pr2_two_cups "):
        authors_trial("authors", PAPER, "pr2_two_cups", lib)
    # their scene, another library: it said "ran no motion ... in scene X (they ran X: compound_1 ...)"
    with pytest.raises(UserError, match="this library has no class 'compound_1', the one the authors ran in scene "
                                        "pr2_two_cups_side_parallel"):
        authors_trial("authors", PAPER, "pr2_two_cups_side_parallel", synthetic)


def test_a_csv_library_is_not_the_papers_for_its_class_names(compound_library, caplog):
    """Any CSV library has a class compound_1: a generated one ran as the authors' motions 25-29, beside their costs."""
    with caplog.at_level("WARNING"):
        assert authors_trial("auto", PAPER, "pr2_two_cups_side_parallel", compound_library) is None
    digest = trial_digest(compound_library, ("compound_1", (0, 1, 2, 3, 4)))
    assert caplog.messages == ["paper protocol: the authors' trials and the comparison with their runs are skipped: "
                               "this library is not the paper's: its compound_1 demonstrations 0, 1, 2, 3, 4 are not "
                               f"the paper's (digest {digest}, the paper's 47c6606b93489145)"]
    with pytest.raises(UserError, match="^--trials authors: this library is not the paper's: its compound_3 "):
        authors_trial("authors", PAPER, "pr2_two_cups_facing", compound_library)


def test_the_paper_library_is_recognised_as_csv_and_npz(paper_library, tmp_path):
    csv = load_library(paper_library, report=False)
    save_library(csv, tmp_path / "paper.npz")
    write_csv_dir(csv, tmp_path / "copy")
    for lib in (csv, load_library(tmp_path / "paper.npz", report=False), load_library(tmp_path / "copy", report=False)):
        assert authors_trial("auto", PAPER, "pr2_two_cups_side_parallel", lib) == ("compound_1", (0, 1, 2, 3, 4))
        assert authors_trial("authors", PAPER, "pr2_two_cups_facing", lib) == ("compound_3", (2,))


def test_move3d_weights_are_the_bodies_reach_and_1_for_the_torso():
    robot = PR2.from_scene(load_scene("pr2_two_cups_side_parallel"))
    w = move3d_path_weights(robot)
    assert w.shape == (8,) and w[0] == 1.0
    assert np.all((w[1:] > 0.02) & (w[1:] < 0.6))  # metres: a PR2 arm link's size
    assert w[3] > w[4] and w[5] > w[6]  # the upper arm and forearm rolls move the long links


def test_the_authors_runs_are_the_papers_table1():
    lp, basic = table1_summary("least_penetration"), table1_summary("basic")
    assert [round(s["mean"], 2) for s in basic] == [24.41, 21.48, 27.53, 24.45, 25.13]
    assert [round(s["mean"], 2) for s in lp] == [0.42, 0.49, 0.61, 0.42, 0.74]
    assert all(len(r) == 10 for runs in TABLE1_RUNS.values() for r in runs)
    assert all(len(t) == 20 for traces in FIG9_TRACES.values() for t in traces.values())
