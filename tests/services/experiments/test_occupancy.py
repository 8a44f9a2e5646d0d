"""``foresight eval occupancy``: the truth, the scores, and a small end-to-end run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from services.experiments.cli import main
from services.experiments.occupancy import occupancy_scores, truth_after, truth_sweep
from shared.human import HumanModel, place_in_scene
from shared.library import save_library
from shared.scene import load_scene
from shared.synthetic import generate_library


@pytest.fixture(scope="module")
def library():
    return generate_library(n_classes=2, n_demos=4, seed=3)


def test_truth_holds_the_demonstrations_own_hand(library) -> None:
    scene = load_scene(None)
    grid = scene.grid
    human = HumanModel()
    for demo in library.demos[:3]:
        f = demo.features
        truth = truth_sweep(f, scene, grid, human)
        for n in (1, len(f) // 2, len(f)):
            occupied = truth_after(truth, n, grid).reshape(grid.dims)
            hand = human.hand_position(place_in_scene(f[n - 1:], f[0], scene))
            idx, inside = grid.index(hand)
            assert inside.all() and occupied[idx[:, 0], idx[:, 1], idx[:, 2]].all()
            if n > 1:  # what is behind is not in the truth any more
                assert occupied.sum() < truth.dense(grid).sum()


def test_scores() -> None:
    truth = np.zeros(1000, bool)
    truth[100:200] = True
    assert occupancy_scores(truth.astype(np.float32), truth) == (1.0, 1.0, 1.0)
    half = np.where(np.arange(1000) < 150, 1.0, 0.0).astype(np.float32)     # 50 of 100 true voxels, 150 predicted
    recall, ratio, ap = occupancy_scores(half, truth)
    assert recall == 0.5 and ratio == 1.5 and 0 < ap < 1
    faint = truth * np.float32(0.05)                                         # below the 0.1 threshold: not counted
    r, v, a = occupancy_scores(faint, truth)
    assert r == 0.0 and v == 0.0 and a == 1.0                               # the ranking is still perfect
    with pytest.raises(ValueError, match="no occupied"):
        occupancy_scores(half, np.zeros(1000, bool))


def test_eval_occupancy_cli(library, tmp_path, capsys) -> None:
    path = tmp_path / "lib.npz"
    save_library(library, path)
    rc = main(["occupancy", "--library", str(path), "--methods", "paper,timed", "--per-class", "1",
               "--components", "2", "--resolution", "0.1", "--n-jobs", "1", "--json", "--out", str(tmp_path)])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert data["fractions"] == [0.2, 0.4, 0.6, 0.8] and data["methods"] == ["paper", "timed"]
    assert data["held_out"] == 2 and data["temperature"] > 0
    for name in ("paper", "timed"):
        m = data[name]
        assert all(0 <= x <= 1 for x in m["recall"] + m["average_precision"]) and min(m["volume_ratio"]) > 0
        assert len(m["recall"]) == len(m["volume_ratio"]) == len(m["average_precision"]) == 4
    assert data["plot"].startswith(str(tmp_path)) and data["plot"].endswith(".png"), data["plot"]
    assert Path(data["plot"]).is_file()
    with pytest.raises(SystemExit) as exc:
        main(["occupancy", "--library", str(path), "--methods", "bogus"])
    assert exc.value.code == 2
    assert "--methods: bogus" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # it drew the last one without a word, after the sweep and training
        main(["occupancy", "--library", str(path), "--per-class", "1", "--example", "2", "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert "--example 2: the held-out demonstrations are 0..1" in capsys.readouterr().err
