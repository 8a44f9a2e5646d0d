"""``python -m tools.reach``: a library's reach points per class, printed and drawn in the scene."""

from __future__ import annotations

import numpy as np
import pytest

from shared.human import HumanModel, reach_points
from shared.library import save_library
from shared.scene import load_scene
from shared.synthetic import SyntheticConfig, generate_library
from tools.reach import main, plot_reach_points


def test_prints_each_class_and_writes_a_png(tmp_path, capsys) -> None:
    lib = generate_library(3, 4, seed=0, config=SyntheticConfig(return_to_rest=True))
    save_library(lib, tmp_path / "lib.npz")
    out = tmp_path / "plots" / "reach.png"
    assert main([str(tmp_path / "lib.npz"), "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[1] for ln in lines[:3]] == lib.class_names
    reach, _ = reach_points(HumanModel(), [d.features for d in lib.demos], load_scene(None))
    labels = np.array([d.label for d in lib.demos])
    mean0 = reach[labels == 0].mean(axis=0)
    assert f"({mean0[0]:+.3f}, {mean0[1]:+.3f}, {mean0[2]:+.3f})" in lines[0]
    assert lines[-1] == f"wrote {out}" and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_draws_goals(tmp_path) -> None:
    reach = np.array([[0.5, -0.4, 0.8], [0.6, -0.3, 0.8]])
    plot_reach_points(reach, np.array([0, 1]), load_scene(None), tmp_path / "p.png", "t", goals=reach)
    assert (tmp_path / "p.png").stat().st_size > 1000


def test_missing_library_is_one_line(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "nope.npz")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not found" in err[0]


@pytest.mark.parametrize("out, text", [("reach", "ending in .png"), ("reach.txt", "ending in .png"), ("", "empty")])
def test_an_output_that_would_not_be_the_png_named_is_refused_first(tmp_path, capsys, out, text) -> None:
    """matplotlib wrote reach.png for --out reach (the tool printed 'wrote reach'), or refused .txt in a traceback."""
    lib = tmp_path / "lib.npz"
    save_library(generate_library(1, 1, seed=0), lib)
    with pytest.raises(SystemExit) as exc:
        main([str(lib), "--out", str(tmp_path / out) if out else ""])
    assert exc.value.code == 2 and text in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib.npz"]


def test_a_library_without_a_valid_demonstration_is_refused(tmp_path, capsys) -> None:
    (tmp_path / "compound_0.csv").write_text("0," + ",".join(["nan"] * 12) + "\n")
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path), "--out", str(tmp_path / "r.png")])
    assert exc.value.code == 2 and "no valid demonstration to draw" in capsys.readouterr().err
