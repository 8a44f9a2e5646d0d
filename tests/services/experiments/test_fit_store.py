"""The fit cache the report's workers share on disk: the same model as without it, each entry made once."""

from __future__ import annotations

import multiprocessing
import time
from pathlib import Path

import numpy as np
import pytest

import services.experiments.fit_store as fit_store_module
import services.predictor.class_volumes as class_volumes
import services.predictor.fit_cache as fit_cache
from services.experiments.fit_store import FitStore, store_tag
from services.predictor.gmm import GMMConfig, fit_class_gmm
from services.predictor.train import TrainConfig, train_model
from services.predictor.volumes import Sweep
from shared.scene import load_scene
from shared.synthetic import generate_library

# a coarse grid and body sampling: the store, not the volumes, is under test
COARSE = dict(gmm=GMMConfig(n_components=2), resolution=0.1, spacing=0.06, oversample=1)


@pytest.mark.parametrize("volume", ["paper", "demos"])
def test_a_model_from_the_store_read_back_is_the_model_without_it(tmp_path, monkeypatch, volume):
    scene = load_scene()
    lib = generate_library(8, 4, seed=1, scene=scene)
    cfg = TrainConfig(volume=volume, **COARSE)  # temperature "auto": its fold fits go through the store too
    plain = train_model(lib, scene, cfg, progress=False)
    train_model(lib, scene, cfg, progress=False, fit_cache=FitStore(tmp_path))
    # every class fit, fold fit and volume or sweep, one file each
    assert len(list((tmp_path / store_tag()).glob("*.npz"))) > 8

    def refused(*_a, **_k):
        raise AssertionError("the store should have given this")

    monkeypatch.setattr(fit_cache, "fit_class_gmm", refused)
    for name in ("sweep", "swept_volume"):
        monkeypatch.setattr(class_volumes, name, refused)
    again = train_model(lib, scene, cfg, progress=False, fit_cache=FitStore(tmp_path))  # another process's view
    assert again.temperature == plain.temperature
    for field in ("weights", "means", "covariances", "motions", "volumes"):
        np.testing.assert_array_equal(getattr(again, field), getattr(plain, field))


def test_entries_read_back_to_the_bit(tmp_path):
    rng = np.random.default_rng(0)
    gmm = fit_class_gmm(rng.normal(size=(200, 3)), GMMConfig(n_components=3))
    sw = Sweep(np.array([3, 7, 9], dtype=np.int64), np.array([0.0, 1.5, 4.0], dtype=np.float32))
    vol = rng.random((4, 5, 6)).astype(np.float32)
    store = FitStore(tmp_path)
    store["g"], store["s"], store["v"] = gmm, sw, vol
    back = FitStore(tmp_path)
    assert "g" in back and "missing" not in back and len(store) == 3
    x = rng.normal(size=(50, 3))
    np.testing.assert_array_equal(back["g"].score_samples(x), gmm.score_samples(x))
    assert back["g"].n_components == 3 and back["g"].converged_ == gmm.converged_
    np.testing.assert_array_equal(back["s"].indices, sw.indices)
    np.testing.assert_array_equal(back["s"].last, sw.last)
    np.testing.assert_array_equal(back["v"], vol)
    with pytest.raises(TypeError, match="cannot store a dict"):
        store["d"] = {"a": 1}
    assert "d" not in FitStore(tmp_path)
    del store["v"]
    assert "v" not in FitStore(tmp_path)


@pytest.mark.parametrize("damage", ["foreign", "empty", "cut short", "a byte flipped"])
def test_an_unreadable_entry_is_made_again(tmp_path, damage):
    store = FitStore(tmp_path)
    store["v"] = np.arange(1000.0)
    (entry,) = store.directory.glob("*.npz")
    data = entry.read_bytes()
    entry.write_bytes({"foreign": b"not an npz", "empty": b"", "cut short": data[:len(data) // 2],
                       "a byte flipped": data[:200] + bytes([data[200] ^ 0xFF]) + data[201:]}[damage])
    assert FitStore(tmp_path).compute("v", lambda: np.arange(4.0)).shape == (4,)
    np.testing.assert_array_equal(FitStore(tmp_path)["v"], np.arange(4.0))  # and written again, whole


def test_entries_of_other_code_are_not_read(tmp_path, monkeypatch):
    FitStore(tmp_path)["v"] = np.arange(3.0)
    assert store_tag() in {p.name for p in tmp_path.iterdir()}
    monkeypatch.setattr(fit_store_module, "MODEL_VERSION", fit_store_module.MODEL_VERSION + 1)  # training changed
    assert "v" not in FitStore(tmp_path)
    assert FitStore(tmp_path).compute("v", lambda: np.arange(4.0)).shape == (4,)


def _make_slowly(directory: str, log: str) -> None:
    def make() -> np.ndarray:
        with open(log, "a") as f:
            f.write("made\n")
        time.sleep(0.5)  # long enough that the other process asks while this one makes it
        return np.arange(5.0)

    np.testing.assert_array_equal(FitStore(Path(directory)).compute("key", make), np.arange(5.0))


def test_processes_asking_at_once_make_the_entry_once(tmp_path):
    log = tmp_path / "made.txt"
    ctx = multiprocessing.get_context("fork")
    procs = [ctx.Process(target=_make_slowly, args=(str(tmp_path / "fits"), str(log))) for _ in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=30)
    try:
        assert [p.exitcode for p in procs] == [0, 0, 0]
    finally:
        for p in procs:
            if p.is_alive():
                p.kill()
                p.join(5)
    assert log.read_text().splitlines() == ["made"]
