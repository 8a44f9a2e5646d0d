"""Occupancy volumes with the motion's spread, time-indexed volumes, and the cross-validated temperature."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from services.predictor.calibration import TEMPERATURE_GRID
from services.predictor.core import PredictorCore
from services.predictor.gmm import GMMConfig
from services.predictor.model import ModelError, PredictionModel
from services.predictor.swept_volume import swept_volume
from services.predictor.train import TrainConfig, train_model
from services.predictor.volumes import VOLUMES, demos_volume, digest, interpolate, spread_volume, sweep, timed_volume
from shared.human import HumanModel

SMALL = TrainConfig(gmm=GMMConfig(n_components=4, max_iter=50), resolution=0.1, oversample=2, temperature=20.0)


@pytest.fixture(scope="module")
def models(small_library, scene) -> dict[str, PredictionModel]:
    cache: dict = {}
    return {v: train_model(small_library, scene, dataclasses.replace(SMALL, volume=v), progress=False,
                           fit_cache=cache) for v in VOLUMES}


def test_zero_spread_gives_the_paper_volume(small_library, scene) -> None:
    grid = scene.grid.with_resolution(0.1)
    mean = interpolate(small_library.by_class(0)[0].features, 2)[0]
    paper = swept_volume(mean, scene, grid, HumanModel())
    spread = spread_volume(mean, np.zeros((len(mean), 12, 12)), scene, grid, n_samples=4)
    assert spread.dtype == np.float32 and np.array_equal(spread, paper.astype(np.float32))
    # with a spread the volume grows and holds the mean's voxels with probability > 0
    cov = np.broadcast_to(np.eye(12) * 1e-3, (len(mean), 12, 12))
    wide = spread_volume(mean, cov, scene, grid, n_samples=8)
    assert np.all((wide >= 0) & (wide <= 1)) and (wide > 0).sum() > paper.sum()


def test_demos_volume_is_the_share_of_demonstrations(small_library, scene) -> None:
    grid = scene.grid.with_resolution(0.1)
    demos = [d.features for d in small_library.by_class(0)[:3]]
    sweeps = [sweep(f, scene, grid, oversample=2) for f in demos]
    # a sweep marks what swept_volume marks along the interpolated motion
    assert np.array_equal(sweeps[0].dense(grid), swept_volume(interpolate(demos[0], 2)[0], scene, grid))
    same = demos_volume([sweeps[0]] * 3, grid)
    assert np.array_equal(same, sweeps[0].dense(grid).astype(np.float32))   # no spread: 1 on the sweep
    vol = demos_volume(sweeps, grid)
    assert np.allclose(vol * 3, np.rint(vol * 3), atol=1e-5) and vol.max() == 1
    support, timed = timed_volume(sweeps, grid, time_bin=10, n_bins=10)
    assert np.allclose(timed[0], vol.ravel()[support])                       # bin 0: the whole motion
    assert np.all(np.diff(timed, axis=0) <= 1e-7)                           # what is still to come shrinks


def test_occupancy_in_unit_interval_and_round_trip(models, small_library, scene, tmp_path) -> None:
    demo = small_library.by_class(2)[0].features
    for name, model in models.items():
        assert model.volume_method == name and model.volumes.min() >= 0 and model.volumes.max() <= 1
        path = tmp_path / f"{name}.npz"
        model.save(path)
        back = PredictionModel.load(path)
        assert back.volume_method == name
        assert np.allclose(back.volumes, model.volumes, atol=1 / 510 + 1e-6)
        assert (back.timed is None) == (name != "timed")
        core = PredictorCore(back, scene)
        core.reset(0)
        for i, f in enumerate(demo):
            res = core.update(f, i)
            assert res.values.min() >= 0 and res.values.max() <= 1
            grid = res.to_message(stamp=0.0, tick=-1, tick_last=True, demo_id=0, index=i).to_dense()
            assert grid.min() >= 0 and grid.max() <= 1
    assert models["paper"].volumes.max() == 1 and set(np.unique(models["paper"].volumes)) <= {0.0, 1.0}
    # the spread volumes hold the paper's voxels and more
    for name in ("spread", "demos"):
        assert (models[name].volumes > 0).sum() > (models["paper"].volumes > 0).sum()


def test_timed_occupancy_drops_what_has_passed(models, small_library, scene) -> None:
    core = PredictorCore(models["timed"], scene)
    post = np.full(small_library.n_classes, 1 / small_library.n_classes)
    idx0, early = core.occupancy_for(post, 0)
    idx1, late = core.occupancy_for(post, 80)
    assert np.array_equal(idx0, idx1) and np.all(late <= early + 1e-7) and late.sum() < early.sum()
    demos = PredictorCore(models["demos"], scene)
    assert np.allclose(demos.occupancy_for(post)[1], early, atol=1e-6)       # t = 0: the demos volume


def test_temperature_chosen_by_cross_validation_is_stored(small_library, scene, tmp_path) -> None:
    cfg = dataclasses.replace(SMALL, temperature=None, folds=2)
    model = train_model(small_library, scene, cfg, progress=False)
    losses = {float(k): v for k, v in model.meta["temperature_log_loss"].items()}
    assert model.meta["temperature_choice"] == "cross-validated" and set(losses) == set(TEMPERATURE_GRID)
    assert model.temperature == min(losses, key=losses.get)
    path = tmp_path / "m.npz"
    model.save(path)
    back = PredictionModel.load(path)
    assert back.temperature == model.temperature
    assert PredictorCore(back, scene).temperature == model.temperature


def test_version_1_model_files_still_load(models, tmp_path) -> None:
    path = tmp_path / "m.npz"
    models["paper"].save(path)
    with np.load(path) as z:
        data = {k: z[k] for k in z.files if k != "volume_method"}
    data["version"] = np.array(1)
    old = tmp_path / "v1.npz"
    np.savez(old, **data)
    back = PredictionModel.load(old)
    assert back.volume_method == "paper" and np.array_equal(back.volumes, models["paper"].volumes)


def test_digest_tells_apart_arrays_of_the_same_bytes():
    a = np.arange(6.0)
    keys = {digest(a), digest(a.reshape(2, 3)), digest(a[:3], a[3:]), digest(a.view(np.int64)),
            digest(a, 1), digest(a, "1")}
    assert len(keys) == 6
    assert digest(a.reshape(2, 3)) == digest(np.arange(6.0).reshape(2, 3))  # a key: the same parts, the same digest


def test_a_timed_support_out_of_order_is_a_model_error(models, tmp_path) -> None:
    models["timed"].save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["timed_support"] = arrays["timed_support"][::-1].copy()
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ModelError, match="timed volumes"):
        PredictionModel.load(tmp_path / "bad.npz")
