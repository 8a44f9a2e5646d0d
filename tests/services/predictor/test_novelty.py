"""The novelty test: familiarity (batched equals frame by frame), the learnt threshold, the core and the model file."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from services.predictor.core import PredictorConfig, PredictorCore, PredictorError
from services.predictor.features import FeatureEncoder
from services.predictor.fit_cache import class_fit
from services.predictor.model import ModelError, PredictionModel
from services.predictor.novelty import (
    SCORE_FLOOR,
    FamiliarityWindow,
    NoveltyTest,
    familiarity,
    heldout_minima,
    learn_novelty,
    least_familiarity,
    through_sensor,
)
from services.predictor.train import TrainConfig, train_model

from .conftest import SMALL


def test_familiarity_batched_equals_looped_and_frame_by_frame():
    rng = np.random.default_rng(3)
    ll = rng.normal(-8.0, 4.0, (41, 3))
    ll[7, 1] = -np.inf
    looped = [np.median(ll[max(0, t - 9): t + 1], axis=0).max() for t in range(len(ll))]
    window = FamiliarityWindow(10)
    live = [window.push(row) for row in ll]
    np.testing.assert_allclose(familiarity(ll, 10), np.maximum(looped, SCORE_FLOOR))
    np.testing.assert_array_equal(familiarity(ll, 10), live)
    window.reset()
    assert window.push(ll[0]) == ll[0].max()  # a new motion starts from its first frame


def test_one_glitch_frame_leaves_the_familiarity_but_a_motion_that_leaves_every_class_drops_it():
    ll = np.full((30, 2), -5.0)
    ll[12] = -5000.0  # one implausible posture
    assert familiarity(ll, 10).min() == -5.0
    first = np.full((30, 2), 10.0)
    first[0] = -5000.0  # a glitch at the first frame: a median of one or two frames is no guard (a review)
    assert familiarity(first, 10)[:3].tolist() == [-5000.0, -2495.0, 10.0]
    assert least_familiarity(familiarity(first, 10)) == 10.0  # judged from the third frame on (MIN_FRAMES)
    ll[15:] = -500.0  # from frame 15 on, no class explains the motion
    s = familiarity(ll, 10)
    assert s[15:19].max() == -5.0 and s[20:].max() == -500.0  # once most of the window is new


def test_the_threshold_is_a_held_out_minimum_and_lets_about_the_quantile_below_it(small_library):
    enc = FeatureEncoder("paper", feature_names=small_library.feature_names)
    feats = [[enc.batch(d.features) for d in small_library.by_class(m)] for m in range(small_library.n_classes)]
    fit = partial(class_fit, gmm=SMALL.gmm, cache={})
    minima = heldout_minima(feats, fit, folds=3)
    assert minima.shape == (len(small_library.demos),)
    for q in (0.0, 0.1, 0.5):
        test = learn_novelty(feats, fit, folds=3, quantile=q)
        assert test is not None and test.threshold in minima and test.heldout == minima.size
        assert (minima < test.threshold).mean() <= q  # these held-out known motions are called unfamiliar
    assert learn_novelty([feats[0], feats[1][:1]], fit, folds=3) is None  # nothing to hold out of class 1


def _play(core: PredictorCore, features: np.ndarray) -> list[bool]:
    core.reset(0)
    out = []
    for t, f in enumerate(features):
        core.observe(f, t)
        out.append(core.familiar)
    return out


def test_a_class_the_model_never_saw_is_called_unfamiliar_and_a_known_one_is_not(two_class_model, small_library,
                                                                                    scene):
    core = PredictorCore(two_class_model, scene)
    unseen = [_play(core, d.features) for d in small_library.by_class(2)]
    known = [_play(core, d.features) for d in small_library.demos if d.label < 2]  # trained on: never below
    assert all(all(k) for k in known)
    assert sum(not all(u) for u in unseen) >= len(unseen) // 2
    assert all(u[0] for u in unseen)  # a motion starts familiar (every reach starts at rest)
    result = core.predict()
    assert result.familiar == core.familiar and result.familiarity == core.familiarity


def test_all_classes_occupancy_keeps_every_class_volume_while_unfamiliar(two_class_model, small_library, scene):
    report = PredictorCore(two_class_model, scene)
    every = PredictorCore(two_class_model, scene, PredictorConfig(unfamiliar="all-classes"))
    demo = next(d for d in small_library.by_class(2) if not all(_play(report, d.features)))
    for core in (report, every):
        _play(core, demo.features)
    assert not every.familiar
    union = two_class_model.volumes.reshape(2, -1).max(axis=0)
    np.testing.assert_array_equal(every.predict().occupancy.ravel(), union)
    assert not np.array_equal(report.predict().occupancy.ravel(), union)  # the posterior's mixture instead
    res = every.predict()  # its values are the core's cached all-classes occupancy: an edit would change the next
    for a in (res.indices, res.values):
        with pytest.raises(ValueError, match="read-only"):
            a[:] = 0
    np.testing.assert_array_equal(every.predict().occupancy.ravel(), union)
    with pytest.raises(PredictorError, match="unfamiliar"):
        PredictorCore(two_class_model, scene, PredictorConfig(unfamiliar="ignore"))


def test_the_model_file_keeps_the_novelty_test_and_older_files_call_every_motion_familiar(two_class_model, scene,
                                                                                            tmp_path):
    path = tmp_path / "m.npz"
    two_class_model.save(path)
    assert PredictionModel.load(path).novelty == two_class_model.novelty
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    older = {k: v for k, v in arrays.items() if not k.startswith("novelty_")}
    np.savez_compressed(tmp_path / "old.npz", **older)
    old = PredictionModel.load(tmp_path / "old.npz")
    assert old.novelty is None
    core = PredictorCore(old, scene)
    core.observe(np.array(two_class_model.motion(0)[0]), 0)
    assert core.familiar
    np.savez_compressed(tmp_path / "bad.npz", **{**arrays, "novelty_threshold": np.array(np.nan)})
    with pytest.raises(ModelError, match="novelty threshold must be finite"):
        PredictionModel.load(tmp_path / "bad.npz")


def test_train_refuses_a_quantile_outside_0_1(small_library, scene):
    from shared.runtime import UserError

    with pytest.raises(UserError, match="--novelty-quantile"):
        train_model(small_library, scene, TrainConfig(novelty_quantile=1.0), progress=False)


def test_novelty_test_checks_its_values():
    with pytest.raises(ValueError, match="window"):
        NoveltyTest(-3.0, window=0)
    with pytest.raises(ValueError, match="quantile"):
        NoveltyTest(-3.0, quantile=1.5)


def test_a_sensor_s_noise_lowers_the_threshold_and_the_model_file_keeps_what_it_was_calibrated_for(
        small_library, small_model, scene, tmp_path):
    """`foresight train --sensor-noise-m`: the held-out demonstrations are scored as the tracker gives a live person's
    (2 cm of keypoint noise fitted back: every known reach fell below the threshold learnt as recorded)."""
    import dataclasses

    from .conftest import _FITS

    noisy = train_model(small_library, scene, dataclasses.replace(SMALL, sensor_noise_m=0.02), progress=False,
                        fit_cache=dict(_FITS))
    clean = small_model.novelty
    assert clean is not None and noisy.novelty is not None
    assert clean.sensor_noise_m == 0.0 and noisy.novelty.sensor_noise_m == 0.02
    assert noisy.novelty.threshold < clean.threshold - 1.0  # the fitted features' error: far less familiar
    assert noisy.novelty.heldout == clean.heldout and "2 cm of noise" in noisy.novelty.describe()
    assert "calibrated for no sensor" in clean.describe()
    np.testing.assert_array_equal(noisy.means, small_model.means)  # the mixtures: fitted to the features as recorded
    path = tmp_path / "noisy.npz"
    noisy.save(path)
    assert PredictionModel.load(path).novelty == noisy.novelty
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    older = {k: v for k, v in arrays.items() if k != "novelty_sensor_noise_m"}  # a file from before: as recorded
    np.savez_compressed(tmp_path / "old.npz", **older)
    assert PredictionModel.load(tmp_path / "old.npz").novelty.sensor_noise_m == 0.0
    np.savez_compressed(tmp_path / "bad.npz", **{**arrays, "novelty_sensor_noise_m": np.array(-0.01)})
    with pytest.raises(ModelError, match="sensor noise"):
        PredictionModel.load(tmp_path / "bad.npz")


def test_no_sensor_noise_is_the_threshold_and_the_file_as_before(small_library, small_model, tmp_path):
    """0 (the default) scores the features as recorded: the threshold is learn_novelty's on them, and the file has
    no new array (a model trained as before is the same file, but for its time of training)."""
    enc = FeatureEncoder("paper", feature_names=small_library.feature_names)
    feats = [[enc.batch(d.features) for d in small_library.by_class(m)] for m in range(small_library.n_classes)]
    fit = partial(class_fit, gmm=SMALL.gmm, cache={})
    assert learn_novelty(feats, fit, folds=3, scored=None) == small_model.novelty
    small_model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as z:
        assert [k for k in z.files if k.startswith("novelty_")] == ["novelty_threshold", "novelty_window",
                                                                    "novelty_quantile", "novelty_heldout"]


def test_through_the_sensor_clean_keypoints_come_back_near_the_features_and_noise_is_seeded(small_library):
    demos = [[d.features for d in small_library.by_class(m)[:2]] for m in range(2)]
    clean = through_sensor(demos, 0.0)
    assert [len(c) for c in clean] == [2, 2] and all(a.shape == b.shape for c, ds in zip(clean, demos, strict=True)
                                                     for a, b in zip(c, ds, strict=True))
    pelvis = np.concatenate([a - b for c, ds in zip(clean, demos, strict=True)
                             for a, b in zip(c, ds, strict=True)])[:, :3]
    assert np.abs(pelvis).max() < 0.05  # the fit's pelvis, One-Euro smoothed (its lag in a step)
    once, again, other = (through_sensor(demos, 0.02, seed) for seed in (0, 0, 1))
    np.testing.assert_array_equal(once[1][0], again[1][0])
    assert not np.array_equal(once[1][0], other[1][0])


def test_train_refuses_a_sensor_noise_it_cannot_calibrate_for(small_library, scene):
    from shared.feature_sets import generic_names
    from shared.runtime import UserError

    with pytest.raises(UserError, match="--sensor-noise-m must be in"):
        train_model(small_library, scene, TrainConfig(sensor_noise_m=-0.01), progress=False)
    import dataclasses

    renamed = dataclasses.replace(small_library, feature_names=generic_names(len(small_library.feature_names)))
    with pytest.raises(UserError, match="--sensor-noise-m .* needs the herakles feature set"):
        train_model(renamed, scene, TrainConfig(sensor_noise_m=0.02), progress=False)
    with pytest.raises(ValueError, match="sensor noise"):
        NoveltyTest(-3.0, sensor_noise_m=float("nan"))
