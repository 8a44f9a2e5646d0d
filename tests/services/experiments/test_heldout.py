"""Held-out models and the class that reaches each cup."""

from __future__ import annotations

import numpy as np
import pytest

from services.experiments.heldout import (
    CupClass,
    HeldOutModels,
    class_at_cup,
    cup_class,
    human_file,
    load_experiment_library,
    short_name,
)
from services.experiments.switch import settle_step
from services.predictor.gmm import GMMConfig
from services.predictor.model import PredictionModel
from services.predictor.train import TrainConfig, train_model
from services.predictor.volumes import DEFAULT_VOLUME, VOLUMES
from shared.library import load_library
from shared.scene import load_scene
from shared.synthetic import generate_library


@pytest.mark.parametrize("name", ["pr2_two_cups", "pr2_two_cups_facing", "pr2_two_cups_side"])
def test_the_synthetic_cup_classes_are_found_at_their_cups(name):
    scene = load_scene(name)
    lib = load_experiment_library("synthetic", scene)
    for cup in ("blue_cup", "red_cup"):
        found = cup_class(lib, scene, cup)
        assert found.name == cup and found.distance < 0.05


def test_a_fit_cache_refits_only_the_changed_class_and_changes_nothing(tmp_path):
    scene = load_scene()
    lib = generate_library(8, 4, seed=1, scene=scene)
    # one volume per class; a coarse grid and body sampling: the cache, not the volumes, is under test
    cfg = TrainConfig(gmm=GMMConfig(n_components=2), temperature=150.0, volume="spread", resolution=0.1, spacing=0.06,
                      oversample=1)
    out = lib.by_class(3)[0]
    demos = [d for d in lib.demos if d is not out]
    cache: dict = {}

    def count(kind: str) -> int:
        return sum(k.split(":")[0] == kind for k in cache)

    train_model(lib, scene, cfg, progress=False, fit_cache=cache)
    # a class fit each, and the novelty test's 3 folds of each (a given temperature fits no folds of its own)
    assert count("gmm") == 8 + 8 * cfg.folds and count("volume") == 8
    cached = train_model(lib, scene, cfg, demos=demos, progress=False, fit_cache=cache)
    # class 3 alone is refitted, with those of its folds whose data changed (a fold may hold the same demonstrations
    # as one before), and gets a new volume
    assert 8 + 8 * cfg.folds + 1 < count("gmm") <= 8 + 8 * cfg.folds + 1 + cfg.folds and count("volume") == 9
    plain = train_model(lib, scene, cfg, demos=demos, progress=False)
    assert all(v.any() for v in cached.volumes)  # every class has a volume to compare
    for field in ("weights", "means", "covariances", "motions", "volumes"):
        np.testing.assert_array_equal(getattr(cached, field), getattr(plain, field))


def test_held_out_models_are_cached_per_held_out_set(tmp_path):
    scene = load_scene()
    lib = generate_library(8, 3, seed=2, scene=scene)
    models = HeldOutModels(lib, scene, tmp_path, components=2)
    a = models.without([lib.by_class(0)[0]])
    b = models.without([lib.by_class(0)[1]])
    assert a != b and models.without([lib.by_class(0)[0]]) == a
    model = PredictionModel.load(a)
    assert model.meta["demos_per_class"][0] == 2 and model.volume_method == DEFAULT_VOLUME
    other = next(v for v in VOLUMES if v != DEFAULT_VOLUME)
    b = HeldOutModels(lib, scene, tmp_path, components=2, volume=other).without([lib.by_class(0)[0]])
    assert b != a and PredictionModel.load(b).volume_method == other


def test_settle_step():
    assert settle_step([]) is None
    assert settle_step(["r"] * 5) == 0
    assert settle_step(["r", "r", "b", "b"]) == 2
    assert settle_step(["r", "b", "r", "b", "b"]) == 3


def test_short_names():
    assert short_name("synthetic:table_8 classes=8") == "synthetic"
    assert short_name("../shared/data/paper-library/") == "paper-library"


def test_away_step():
    from services.experiments.switch import away_step

    assert away_step(["b", "b"], "r") == 0
    assert away_step(["r", "r", "b", "b"], "r") == 2
    assert away_step(["r", "b", "r", "b"], "r") == 3
    assert away_step(["b", "r"], "r") is None and away_step([], "r") is None


def test_human_files_of_two_libraries_never_collide(tmp_path):
    """Both libraries of a report write into one work directory; class 1 demo 0 of each is its own file."""
    a, b = generate_library(n_classes=3, n_demos=2, seed=1), generate_library(n_classes=3, n_demos=2, seed=2)
    da, db = a.by_class(1)[0], b.by_class(1)[0]
    assert (da.label, da.index) == (db.label, db.index)
    pa, pb = human_file(a, da, tmp_path), human_file(b, db, tmp_path)
    assert pa != pb
    assert human_file(a, da, tmp_path) == pa  # written once, found again
    np.testing.assert_array_equal(load_library(pb).demos[0].features, db.features)
    np.testing.assert_array_equal(load_library(pa).demos[0].features, da.features)


def test_a_given_class_takes_the_cup_nearest_its_reach_unless_one_is_named():
    scene = load_scene("pr2_two_cups_facing")
    lib = generate_library(8, 3, seed=0, scene=scene)
    red = cup_class(lib, scene, "red_cup")
    assert class_at_cup(lib, scene, None, red.label) == red  # its own cup, at the same distance
    named = class_at_cup(lib, scene, "blue_cup", red.label)
    assert named.cup == "blue_cup" and named.distance > red.distance


def test_a_human_file_written_by_many_at_once_is_always_whole(tmp_path) -> None:
    """Report workers share the humans directory: a reader could load a file another writer had half-written."""
    from concurrent.futures import ThreadPoolExecutor

    lib = generate_library(2, 3, seed=0)
    demo = lib.demos[0]

    def write_and_read(_: int) -> int:
        return len(load_library(human_file(lib, demo, tmp_path)).demos)

    for _ in range(5):
        for f in tmp_path.glob("*.npz"):
            f.unlink()
        with ThreadPoolExecutor(8) as pool:
            assert list(pool.map(write_and_read, range(16))) == [1] * 16
    assert [f.name for f in tmp_path.iterdir() if f.name.startswith(".")] == []  # no temporary file left


def test_a_class_far_from_its_cup_is_warned_about_and_every_demonstration_held_out_refused() -> None:
    """--demos above the class's size held every demonstration out ('no demonstrations for class(es)'), and a
    class ending 0.72 m from the cup gave a Table I ratio without a word."""
    from shared.runtime import UserError

    near, far = CupClass("blue_cup", 0, "blue_cup", 0.014), CupClass("blue_cup", 0, "compound_0", 0.716)
    assert near.warning() == ""
    assert far.warning().startswith("warning: class compound_0's mean reach ends 0.72 m from blue_cup, more than 0.3")
    assert near.held_out(3, 2) == 2
    for demos in (3, 5):
        with pytest.raises(UserError, match=rf"--demos {demos}: class blue_cup has 3 demonstrations, .* at most 2"):
            near.held_out(3, demos)

