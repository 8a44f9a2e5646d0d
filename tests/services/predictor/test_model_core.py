from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest

from services.predictor.core import PredictorConfig, PredictorCore, PredictorError
from services.predictor.features import VARIANTS, FeatureEncoder
from services.predictor.gmm import GMMConfig, MixtureBank, fit_class_gmm
from services.predictor.model import ModelError, PredictionModel
from shared.human import HumanModel, place_in_scene
from shared.protocol import OccupancyGrid, decode, encode


def _meta(i: int) -> dict:
    return {"stamp": 0.0, "tick": -1, "tick_last": True, "demo_id": 0, "index": i}


def test_model_round_trip(small_model: PredictionModel, tmp_path) -> None:
    path = tmp_path / "m.npz"
    small_model.save(path)
    back = PredictionModel.load(path)
    assert back.class_names == small_model.class_names
    assert back.grid.dims == small_model.grid.dims
    assert back.volume_method == small_model.volume_method
    assert np.array_equal(back.volumes, small_model.volumes)  # the trainer quantises as the file does
    assert np.allclose(back.covariances, small_model.covariances)
    assert np.allclose(back.motions, small_model.motions)
    assert back.meta["components"] == [4, 4, 4]


def test_model_rejects_wrong_version_corrupt_and_missing(paper_model: PredictionModel, tmp_path) -> None:
    path = tmp_path / "m.npz"
    paper_model.save(path)  # version 1 files held bit-packed paper volumes
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    data["version"] = np.array(99)
    other = tmp_path / "v99.npz"
    np.savez(other, **data)
    with pytest.raises(ValueError, match="version 99"):
        PredictionModel.load(other)
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(path.read_bytes()[:2000])
    with pytest.raises(ValueError, match="corrupt"):
        PredictionModel.load(corrupt)
    with pytest.raises(ValueError, match="foresight train"):
        PredictionModel.load(tmp_path / "missing.npz")
    data["version"] = np.array(1)
    data["volumes"] = data["volumes"][:, :-3]
    bad = tmp_path / "bad.npz"
    np.savez(bad, **data)
    with pytest.raises(ValueError, match="volumes"):
        PredictionModel.load(bad)


def test_swept_volume_contains_regressed_hand_path(paper_model: PredictionModel, scene) -> None:
    human = HumanModel()
    for m in range(paper_model.n_classes):
        mot = paper_model.motion(m)
        hand = human.hand_position(place_in_scene(mot, mot[0], scene))
        idx, inside = paper_model.grid.index(hand)
        assert inside.all()
        assert paper_model.volumes[m][idx[:, 0], idx[:, 1], idx[:, 2]].all()


def test_swept_volume_contains_demo_hand_positions(paper_model: PredictionModel, small_library, scene) -> None:
    """Every demonstration's hand stays within one voxel of its class's (paper) swept volume."""
    from scipy.ndimage import binary_dilation

    human = HumanModel()
    for m in range(paper_model.n_classes):
        vol = binary_dilation(paper_model.volumes[m], iterations=1)
        for d in small_library.by_class(m):
            hand = human.hand_position(place_in_scene(d.features, d.features[0], scene))
            idx, inside = paper_model.grid.index(hand)
            assert inside.all()
            assert vol[idx[:, 0], idx[:, 1], idx[:, 2]].mean() >= 0.95


def test_posterior_and_occupancy(small_model: PredictionModel, small_library, scene) -> None:
    core = PredictorCore(small_model, scene)
    demo = small_library.by_class(2)[1]
    core.reset(7)
    for i, f in enumerate(demo.features):
        res = core.update(f, i)
        assert np.isclose(res.posterior.sum(), 1.0) and np.all(res.posterior >= 0)
        occ = res.occupancy
        assert occ.shape == small_model.grid.dims and occ.dtype == np.float32
        assert occ.min() >= 0.0 and occ.max() <= 1.0
    assert int(np.argmax(res.posterior)) == 2
    # the indices are the union of the class volumes, the core's own array: read-only, or an edit would move
    # every later prediction's voxels
    assert np.array_equal(res.indices, np.flatnonzero(small_model.volumes.reshape(small_model.n_classes, -1)
                                                      .any(axis=0)))
    for a in (res.indices, res.values, core.support):
        with pytest.raises(ValueError, match="read-only"):
            a[:1] = 0
    # one-hot posterior: the occupancy is that class's swept volume
    for m in range(small_model.n_classes):
        idx, val = core.occupancy_for(np.eye(small_model.n_classes)[m])
        dense = np.zeros(small_model.volumes[m].size, np.float32)
        dense[idx] = val
        assert np.array_equal(dense.reshape(small_model.grid.dims), small_model.volumes[m].astype(np.float32))
    # the wire message equals OccupancyGrid.from_dense of the dense grid
    msg = res.to_message(**_meta(99))
    ref = OccupancyGrid.from_dense(res.occupancy, small_model.grid.min, small_model.grid.resolution,
                                   method="prediction", **_meta(99))
    assert np.array_equal(msg.indices, ref.indices) and np.array_equal(msg.values, ref.values)
    back = decode(encode(msg), OccupancyGrid)
    assert np.allclose(back.to_dense(), res.occupancy, atol=0.5 / 255 + 1e-6)


def test_reset_and_incremental_matches_batch(small_model: PredictionModel, small_library, scene) -> None:
    core = PredictorCore(small_model, scene)
    demo = small_library.by_class(0)[0].features
    enc = small_model.encoder()
    batch = small_model.bank().log_likelihood(enc.batch(demo)).sum(axis=0)
    for _ in range(2):  # the second pass checks that reset forgets everything
        core.reset(1)
        for i, f in enumerate(demo):
            res = core.update(f, i)
        assert np.allclose(res.log_likelihood, batch)


def test_current_occupancy_is_the_posture(small_model: PredictionModel, small_library, scene) -> None:
    core = PredictorCore(small_model, scene, PredictorConfig(method="current"))
    demo = small_library.by_class(0)[0].features
    core.reset(0)
    core.update(demo[0], 0)
    res = core.update(demo[50], 50)
    occ = res.occupancy
    assert set(np.unique(occ)) <= {0.0, 1.0} and occ.sum() > 20
    hand = HumanModel().hand_position(place_in_scene(demo[50], demo[0], scene))
    idx, inside = small_model.grid.index(hand[None])
    i, j, k = idx[0]
    assert inside[0] and occ[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2, max(k - 1, 0):k + 2].sum() > 0
    pelvis = small_model.grid.index(np.asarray(scene.human.pelvis_xyz)[None])[0][0]
    assert occ[max(pelvis[0] - 2, 0):pelvis[0] + 3, max(pelvis[1] - 2, 0):pelvis[1] + 3].sum() > 0


def test_bad_input_rejected(small_model: PredictionModel, small_library, scene) -> None:
    core = PredictorCore(small_model, scene)
    core.reset(0)
    with pytest.raises(PredictorError, match="12 finite"):
        core.update(np.zeros(11))
    with pytest.raises(PredictorError, match="NaN"):
        core.update(np.full(12, np.nan))
    demo = small_library.demos[0].features
    core.observe(demo[0])
    huge = demo[1].copy()
    huge[0] = 1e200  # finite, but every class's log-likelihood overflowed to -inf and stayed so for good
    with pytest.raises(PredictorError, match=r"pelvis_x = 1e\+200 outside its plausible range"):
        core.observe(huge)
    after = core.observe(demo[1])  # the refused posture left no trace
    twin = PredictorCore(small_model, scene)
    twin.reset(0)
    twin.observe(demo[0])
    np.testing.assert_array_equal(after, twin.observe(demo[1]))
    assert not np.allclose(after, 1.0 / len(after))
    with pytest.raises(PredictorError, match="method"):
        PredictorCore(small_model, scene, PredictorConfig(method="bogus"))



def test_a_model_whose_grid_the_planner_would_refuse_is_named(small_model: PredictionModel,
                                                                         scene) -> None:
    """A scene whose grid differs from the model's: the predictor started, and the planner refused every grid it
    published (``OccupancyGrid.origin: [-1.0, ...] is not the scene grid's [-1.2, ...]``)."""
    from shared.scene import Grid

    g = scene.grid
    shifted = dataclasses.replace(scene, grid=Grid(g.min - np.array([0.2, 0.0, 0.0]), g.max, g.resolution))
    with pytest.raises(ModelError, match=r"model: its grid \(origin: .* is not the scene grid's .*\) is not one the "
                                         r"planner of scene 'pr2_two_cups' takes"):
        small_model.check_planner_grid(shifted)
    coarse = dataclasses.replace(scene, grid=Grid(g.min, g.max, 0.25))  # the model's 0.1 m: finer than 0.125
    with pytest.raises(ModelError, match=r"resolution: 0.1 m is finer than the 0.125 m this receiver takes"):
        small_model.check_planner_grid(coarse)
    small_model.check_planner_grid(scene)  # the model's 0.1 m on the scene's bounds: taken


def test_an_index_that_repeats_goes_back_or_is_no_whole_number_is_refused(small_model, small_library, scene) -> None:
    """A repeated pose counted its evidence twice (the log-likelihoods moved from [519, 223, -226] to [537, 220,
    -291]), an index going back was taken as well, and 2.7, True or "5" were coerced (a review)."""
    demo = small_library.demos[0].features
    core, twin = PredictorCore(small_model, scene), PredictorCore(small_model, scene)
    core.reset(0)
    twin.reset(0)
    for i in range(10):
        core.observe(demo[i], i)
        twin.observe(demo[i], i)
    for index, said in ((9, "index 9 is not after the last observed .9."), (5, "index 5 is not after"),
                        (0, "index 0 is not after"), (-1, "index must be >= 0, got -1"),
                        (10.0, "a whole number, got 10.0"), (True, "got True"), ("11", "got '11'"),
                        (float("nan"), "got nan")):
        with pytest.raises(PredictorError, match=said):
            core.observe(demo[10], index)
    np.testing.assert_array_equal(core.observe(demo[10], np.int64(12)), twin.observe(demo[10], 12))  # no trace left


def test_temperature_from_model_and_config(small_model: PredictionModel, small_library, scene, tmp_path) -> None:
    from dataclasses import replace

    from services.predictor.gmm import posterior_from_log_likelihood

    demo = small_library.by_class(1)[2].features[:40]
    paper = PredictorCore(small_model, scene, PredictorConfig(temperature=1.0))
    hot_model = replace(small_model, temperature=8.0)
    hot = PredictorCore(hot_model, scene)                       # temperature 0 in the config: the model's
    assert paper.temperature == 1.0 and hot.temperature == 8.0
    assert PredictorCore(hot_model, scene, PredictorConfig(temperature=2.0)).temperature == 2.0
    for core in (paper, hot):
        core.reset(0)
    for i, f in enumerate(demo):
        a, b = paper.update(f, i), hot.update(f, i)
        # tau = 1: the paper's posterior of the summed log-likelihoods (the behaviour before tempering)
        assert np.array_equal(a.posterior, posterior_from_log_likelihood(a.log_likelihood))
        assert np.allclose(b.log_likelihood, a.log_likelihood)
        assert np.allclose(b.posterior, posterior_from_log_likelihood(a.log_likelihood / 8.0))
        assert np.isclose(b.posterior.sum(), 1.0) and np.argmax(b.posterior) == np.argmax(a.posterior)
        # the occupancy is built from the tempered posterior
        idx, val = hot.occupancy_for(b.posterior)
        assert np.array_equal(b.indices, idx) and np.allclose(b.values, val)
    assert b.posterior.max() < a.posterior.max()                # tempered: less confident
    # the model file keeps the temperature; a file without one (written before) means tau = 1
    path = tmp_path / "hot.npz"
    hot_model.save(path)
    assert PredictionModel.load(path).temperature == 8.0
    with np.load(path) as z:
        data = {k: z[k] for k in z.files if k != "temperature"}
    old = tmp_path / "old.npz"
    np.savez(old, **data)
    assert PredictionModel.load(old).temperature == 1.0
    data["temperature"] = np.array(-1.0)
    np.savez(old, **data)
    with pytest.raises(ValueError, match="temperature"):
        PredictionModel.load(old)
    with pytest.raises(PredictorError, match="temperature"):
        PredictorCore(small_model, scene, PredictorConfig(temperature=-2.0))


@pytest.mark.parametrize("variant", VARIANTS)
def test_core_log_likelihood_is_the_batch_sum(small_library, small_model: PredictionModel, scene, variant) -> None:
    """One bank evaluation per pose adds up to the batch ln p(xi | C_m) of the whole demonstration."""
    enc = FeatureEncoder(variant, small_model.time_scale, small_model.velocity_scale)
    fits = [fit_class_gmm(np.vstack([enc.batch(d.features) for d in small_library.by_class(m)]),
                          GMMConfig(n_components=3, max_iter=30)) for m in range(small_library.n_classes)]
    bank = MixtureBank.from_sklearn(fits)
    model = dataclasses.replace(small_model, feature_variant=variant, weights=bank.weights_, means=bank.means_,
                                covariances=bank.covariances_)
    core = PredictorCore(model, scene)
    demo = small_library.by_class(1)[0].features
    core.reset(7)
    for i, f in enumerate(demo):
        result = core.update(f, i)
    batch = bank.log_likelihood(enc.batch(demo)).sum(axis=0)
    assert core.n_observed == len(demo)
    assert np.allclose(core.log_likelihood(), batch, rtol=1e-10, atol=1e-8)
    assert np.array_equal(result.log_likelihood, core.log_likelihood())
    core.reset(8)  # a new demonstration starts from nothing
    assert core.n_observed == 0 and np.array_equal(core.log_likelihood(), np.zeros(small_library.n_classes))


def test_mean_evidence_is_the_softmax_of_the_per_frame_mean(small_model: PredictionModel, small_library, scene) -> None:
    from services.predictor.gmm import posterior_from_log_likelihood

    demo = small_library.by_class(1)[2].features[:30]
    summed = PredictorCore(small_model, scene, PredictorConfig(temperature=1.0))
    mean = PredictorCore(small_model, scene, PredictorConfig(temperature=1.0, evidence="mean"))
    for core in (summed, mean):
        core.reset(0)
    for i, f in enumerate(demo):
        a, b = summed.update(f, i), mean.update(f, i)
        assert np.array_equal(a.log_likelihood, b.log_likelihood)  # the evidence is the same, its weight is not
        assert np.allclose(b.posterior, posterior_from_log_likelihood(a.log_likelihood / (i + 1)))
    assert b.posterior.max() < a.posterior.max()  # the authors' mean is less confident than the paper's product


def test_mean_evidence_with_the_models_temperature_is_refused(small_model: PredictionModel, scene) -> None:
    """The model's tau is chosen on summed evidence: with 'mean' it divided the frames' evidence twice over, and the
    posterior stayed within 0.01 of uniform on the paper's library."""
    with pytest.raises(PredictorError, match="evidence 'mean' needs predictor.temperature set"):
        PredictorCore(small_model, scene, PredictorConfig(evidence="mean"))
    with pytest.raises(ValueError, match="evidence 'mean' needs predictor.temperature set"):
        PredictorConfig(evidence="mean").validate()
    PredictorConfig(evidence="mean", temperature=1.0).validate()


def test_a_posture_held_past_the_training_motions_is_scored_at_their_last_index(small_model: PredictionModel,
                                                                                small_library, scene) -> None:
    """Postures after the last index the mixtures were fitted on were scored at their own index: the class with the
    widest last Gaussians in time won, whatever the posture (8 % recognised at index 200 on the paper's library)."""
    last = small_model.last_index
    assert last == max(d.n_samples for d in small_library.demos) - 1 == small_model.meta["last_index"]
    enc = small_model.encoder()
    assert enc.step(small_library.demos[0].features[0], last + 50)[0] == last * small_model.time_scale
    demo = small_library.by_class(1)[0].features
    held = np.vstack([demo, np.repeat(demo[-1:], 60, axis=0)])        # the human holds the final posture
    core = PredictorCore(small_model, scene)
    core.reset(0)
    steps = [core.log_likelihood()]
    for i, f in enumerate(held):
        core.observe(f, i)
        steps.append(core.log_likelihood())
    gain = np.diff(np.array(steps), axis=0)                          # (T, M) each posture's evidence
    assert len(demo) - 1 == last
    assert np.allclose(gain[-1], gain[last], rtol=1e-9, atol=1e-6)   # the same posture, scored at the same time
    assert np.argmax(core.log_likelihood()) == 1
    # a model file from before the index was recorded: its longest class motion's last sample
    old = dataclasses.replace(small_model, meta={k: v for k, v in small_model.meta.items() if k != "last_index"})
    assert old.last_index == int(np.max(small_model.motion_lengths)) - 1
    batch = FeatureEncoder(last_index=3).batch(demo[:6])
    assert batch[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 3.0, 3.0]


def test_the_velocity_over_a_missing_pose_is_the_change_per_sample(small_library) -> None:
    """A refused or dropped pose between two made the live velocity the change of two samples (training's: one)."""
    demo = small_library.demos[0].features[:5]
    full = FeatureEncoder("relative_velocity").batch(demo)
    enc = FeatureEncoder("relative_velocity")
    got = {i: enc.step(demo[i], i) for i in (0, 1, 3, 4)}           # pose 2 never arrives
    for i in (0, 1, 4):
        assert np.array_equal(got[i], full[i])
    assert np.allclose(got[3][-5:], (full[2][-5:] + full[3][-5:]) / 2)  # the mean change over samples 2 and 3


@pytest.mark.parametrize(("key", "value", "match"), [
    ("time_scale", np.array(np.nan), "time_scale must be a finite number > 0"),
    ("velocity_scale", np.array(np.inf), "velocity_scale must be a finite number > 0"),
    ("spacing", np.array(0.0), "spacing must be a finite number > 0"),
    ("human_pelvis", np.zeros(3), r"human_pelvis must be 4 finite numbers .* shape \(3,\)"),
    ("version", np.array("abc"), "has version abc"),
    # a review's hand-made files (2026-11-28): tracebacks, warnings, or a message that named no field
    ("version", np.array(2.9), "has version 2.9"),
    ("meta", np.array("[]"), "meta must be a JSON object, got list"),
    ("meta", np.array('{"last_index": 1e400}'), "meta.last_index must be an integer >= 0, got inf"),
    ("grid_resolution", np.array(0.0), r"grid_resolution must be a finite number > 0 \(m\), got 0.0"),
    ("grid_resolution", np.array(np.nan), "grid_resolution must be a finite number > 0"),
    ("grid_max", np.array([1.0, 2.0, np.inf]), "grid_max must be 3 finite numbers"),
    ("grid_min", np.array([9.0, 9.0, 9.0]), "grid_max .* must exceed grid_min"),
    ("class_names", np.array([], dtype=str), "it has no classes"),
    ("weights", None, "it has no array 'weights'"),
    ("volume_method", np.array("timed"), "volume method 'timed' but no timed_values"),
    ("interior", np.array("False"), "interior must be a boolean"),
])
def test_a_model_file_with_a_bad_scalar_is_a_model_error(small_model, tmp_path, key, value, match) -> None:
    """These used to load (and fail at run time) or end in a ValueError traceback, not a ModelError."""
    small_model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays[key] = value
    np.savez(tmp_path / "bad.npz", **{k: v for k, v in arrays.items() if v is not None})
    with pytest.raises(ModelError, match=match):
        PredictionModel.load(tmp_path / "bad.npz")


@pytest.mark.parametrize(("change", "match"), [
    (lambda w: w * np.r_[-1.0, np.ones(w.shape[0] - 1)], "mixing weights must be >= 0 and sum to 1"),
    (lambda w: w * 0.5, r"mixing weights must be >= 0 and sum to 1, got .* \(sum 0.5\)"),
])
def test_a_model_file_with_bad_mixing_weights_is_a_model_error(small_model, tmp_path, change, match) -> None:
    """A negative weight loaded and the predictor then published a NaN posterior (refused on the wire) forever."""
    small_model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["weights"] = arrays["weights"].copy()
    arrays["weights"][0] = change(arrays["weights"][0])
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ModelError, match=match):
        PredictionModel.load(tmp_path / "bad.npz")


def test_a_model_path_that_is_no_model_file_says_what_it_is(tmp_path) -> None:
    """A directory was 'not found; run foresight train' (it exists), a .npy a TypeError traceback."""
    with pytest.raises(ModelError, match="is a directory; give the model file itself"):
        PredictionModel.load(tmp_path)
    np.save(tmp_path / "one.npy", np.arange(3))
    with pytest.raises(ModelError, match=r"holds one numpy array \(int64 \(3,\)\), not a model"):
        PredictionModel.load(tmp_path / "one.npy")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file: the check needs another user")
def test_an_unreadable_model_file_names_its_owner_not_corruption(small_model, tmp_path) -> None:
    small_model.save(tmp_path / "m.npz")
    (tmp_path / "m.npz").chmod(0)
    with pytest.raises(ModelError, match=r"cannot read it \(owner uid \d+, mode 0\)"):
        PredictionModel.load(tmp_path / "m.npz")


def test_the_relative_yaw_is_wrapped_to_a_half_turn_either_way() -> None:
    """yaw0 = 3.1, yaw = -3.1 gave -6.2 where the pelvis had turned 0.083 rad: a class's yaw split at the half turn."""
    first = np.zeros(12)
    first[3] = 3.1
    yaws = np.array([-3.1, 3.1, 3.1 - math.pi, 3.1 + math.pi, 3.0])
    postures = np.repeat(first[None], len(yaws), axis=0)
    postures[:, 3] = yaws
    want = [2 * math.pi - 6.2, 0.0, math.pi, math.pi, -0.1]  # (-pi, pi]: a half turn either way is +pi
    for variant in ("relative", "relative_velocity"):
        batch = FeatureEncoder(variant).batch(np.vstack([first, postures]))
        np.testing.assert_allclose(batch[1:, 4], want, atol=1e-12)
        enc = FeatureEncoder(variant)
        enc.step(first, 0)
        np.testing.assert_allclose([enc.step(p, i + 1)[4] for i, p in enumerate(postures)], want, atol=1e-12)
