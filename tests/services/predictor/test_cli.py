"""foresight train / eval recognition / bench predictor on tiny inputs (contracts, not quality)."""

from __future__ import annotations

import json

import pytest

from services.bench import main as bench_main
from services.predictor.bench import run_bench
from services.predictor.model import PredictionModel
from services.predictor.recognition import main as eval_main
from services.predictor.train import main as train_main
from shared.library import save_library
from shared.synthetic import generate_library


@pytest.fixture(scope="module")
def tiny_library_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("lib") / "tiny.npz"
    save_library(generate_library(n_classes=2, n_demos=4, seed=3), path)
    return path


def test_train_cli_writes_a_loadable_model(tiny_library_path, tmp_path, capsys) -> None:
    out = tmp_path / "m.npz"
    assert train_main(["--library", str(tiny_library_path), "--out", str(out), "--components", "2",
                       "--resolution", "0.03", "--quiet"]) == 0
    model = PredictionModel.load(out)
    assert model.grid.resolution == 0.03 and model.n_classes == 2
    assert model.volumes.shape == (2, *model.grid.dims) and model.volumes.any(axis=(1, 2, 3)).all()
    assert "wrote" in capsys.readouterr().out


def test_train_cli_bad_options_are_one_line_errors(tiny_library_path, tmp_path, capsys) -> None:
    for argv in (["--library", str(tmp_path / "nope")], ["--library", str(tiny_library_path), "--components", "-1"],
                 ["--library", str(tiny_library_path), "--resolution", "0"]):
        with pytest.raises(SystemExit) as exc:
            train_main([*argv, "--out", str(tmp_path / "x.npz"), "--quiet"])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "error" in err[0]


def test_train_says_which_class_a_cross_validation_fold_cannot_fit(tmp_path, capsys) -> None:
    """Each class had samples for its Gaussians, a fold without one of its demonstrations had not: a traceback ending
    in "cannot fit 20 Gaussians to 15 samples", naming neither the class nor the fold (a review)."""
    import dataclasses

    lib = generate_library(n_classes=2, n_demos=2, seed=3)
    path = tmp_path / "short.npz"
    save_library(dataclasses.replace(lib, demos=[dataclasses.replace(d, features=d.features[:15]) for d in lib.demos]),
                 path)
    with pytest.raises(SystemExit) as exc:
        train_main(["--library", str(path), "--out", str(tmp_path / "m.npz"), "--components", "20", "--quiet"])
    assert exc.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert (f"class {lib.class_names[0]} without its demonstration(s) [0] (cross-validation fold 0" in line
            and "cannot fit 20 Gaussians to 15 samples; fewer Gaussians (--components)" in line), line


def test_train_says_which_class_it_cannot_fit(tmp_path, capsys) -> None:
    """A class with fewer samples than Gaussians: "cannot fit 30 Gaussians to 24 samples", of no class named."""
    import dataclasses

    lib = generate_library(n_classes=2, n_demos=2, seed=3)
    path = tmp_path / "short.npz"
    demos = [dataclasses.replace(d, features=d.features[:12]) if d.label == 1 else d for d in lib.demos]
    save_library(dataclasses.replace(lib, demos=demos), path)
    with pytest.raises(SystemExit) as exc:
        train_main(["--library", str(path), "--out", str(tmp_path / "m.npz"), "--components", "30", "--quiet"])
    assert exc.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert f"class {lib.class_names[1]} (2 demonstration(s)): cannot fit 30 Gaussians to 24 samples" in line, line


def test_train_refuses_an_out_it_cannot_write_before_it_trains(tiny_library_path, tmp_path, capsys,
                                                               monkeypatch) -> None:
    """A directory in the way was found after the whole training, named as a temporary file."""
    import services.predictor.train as train

    monkeypatch.setattr(train, "train_model", lambda *a, **k: pytest.fail("trained before checking --out"))
    (tmp_path / "dir.npz").mkdir()
    with pytest.raises(SystemExit):
        train_main(["--library", str(tiny_library_path), "--out", str(tmp_path / "dir.npz"), "--quiet"])
    assert f"{tmp_path / 'dir.npz'}: a directory is in the way" in capsys.readouterr().err


def test_eval_recognition_json(tiny_library_path, tmp_path, capsys) -> None:
    png = tmp_path / "rec.png"
    assert eval_main(["recognition", "--library", str(tiny_library_path), "--components", "2", "--n-jobs", "1",
                      "--json", "--plot", str(png), "--quiet", "--temperature", "4", "--temperatures", "1,4,16",
                      "--calibration-plot", str(tmp_path / "cal.png")]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    data = json.loads(out[0])
    assert len(data["fractions"]) == len(data["recognition_rates"]) == 10
    assert all(0.0 <= r <= 1.0 for r in data["recognition_rates"])
    assert png.stat().st_size > 0
    # calibration of the posteriors: log-loss and Brier score per fraction at tau = 1 and --temperature
    assert data["temperature"] == 4.0
    for key in ("log_loss", "log_loss_tau1", "brier", "brier_tau1"):
        assert len(data[key]) == 10 and all(v >= 0.0 for v in data[key]), key
    assert all(b <= 2.0 for b in data["brier"])
    assert set(data["mean_log_loss_by_temperature"]) == {"1", "4", "16"}
    best = data["best_temperature"]
    assert data["mean_log_loss_by_temperature"][f"{best:g}"] == min(data["mean_log_loss_by_temperature"].values())
    assert (tmp_path / "cal.png").stat().st_size > 0


def test_bench_figures(small_model, small_library, scene) -> None:
    res = run_bench(small_model, scene, [small_library.demos[0].features[:20]])
    assert res["updates"] == 20 and res["update_ms_median"] > 0
    assert res["grid_dims"] == list(small_model.grid.dims)


def test_bench_dispatch_unknown(capsys) -> None:
    assert bench_main(["nothing"]) == 2
    assert "unknown benchmark" in capsys.readouterr().err
    assert bench_main([]) == 2  # usage, no benchmark named
