"""``foresight library convert`` to the paper's CSVs, and what ``info`` says of a converted library and its issues."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shared.library import load_library, save_library, write_csv_dir
from shared.synthetic import generate_library
from tools.library import main as library_main


def make_lib(directory: Path) -> Path:
    """3 classes of 4 valid demonstrations in the paper's CSV format."""
    write_csv_dir(generate_library(3, 4, seed=0), directory)
    return directory


def test_convert_writes_a_csv_directory(tmp_path, capsys):
    """docs/prediction.md named ``library convert`` a way to a CSV copy; it refused every output but a .npz."""
    npz = tmp_path / "lib.npz"
    lib = generate_library(3, 4, seed=0)
    save_library(lib, npz)
    assert library_main(["convert", str(npz), "--out", str(tmp_path / "csv")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"wrote {tmp_path / 'csv'}/ (3 CSV files): 12 demonstrations in 3 classes")
    assert f"classes {', '.join(lib.class_names)} are named compound_0, compound_1, compound_2 there" in out
    back = load_library(tmp_path / "csv", report=False)
    assert back.issues == [] and all(np.array_equal(a.features, b.features)
                                     for a, b in zip(lib.demos, back.demos, strict=True))
    with pytest.raises(SystemExit) as exc:
        library_main(["convert", str(npz), "--out", str(tmp_path / "x.csv")])
    assert exc.value.code == 2 and "give a .npz file or a directory (no extension)" in capsys.readouterr().err


def test_info_names_the_npz_and_what_it_was_converted_from(tmp_path, capsys):
    make_lib(tmp_path / "csv")
    assert library_main(["convert", str(tmp_path / "csv"), "--out", str(tmp_path / "mylib.npz")]) == 0
    capsys.readouterr()
    assert library_main(["info", str(tmp_path / "mylib.npz")]) == 0
    assert capsys.readouterr().out.splitlines()[0] == f"library: {tmp_path / 'mylib.npz'} (converted from " \
                                                      f"{tmp_path / 'csv'})"
    assert library_main(["validate", str(tmp_path / "mylib.npz")]) == 0
    assert capsys.readouterr().out.startswith(f"{tmp_path / 'mylib.npz'}: 12 valid demonstrations")


def test_info_counts_a_class_s_issues_not_their_summary(tmp_path, capsys):
    """Two dead blocks said ``issues 3``: the "holds no valid demonstration" line counted as one more."""
    make_lib(tmp_path / "csv")
    rows = np.loadtxt(tmp_path / "csv" / "compound_1.csv", delimiter=",")
    rows = rows[: 2 * int(np.flatnonzero(rows[:, 0] == 0)[1])]
    rows[:, -1] = 0.0  # a dead channel in both blocks
    np.savetxt(tmp_path / "csv" / "compound_1.csv", rows, delimiter=",", fmt=["%d"] + ["%.17g"] * 12)
    (tmp_path / "csv" / "compound_2.csv").write_text("")  # no block at all: its one line is its issue
    assert library_main(["info", str(tmp_path / "csv")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[3].split()[1:3] == ["compound_1", "0"] and lines[3].endswith("issues 2")
    assert lines[4].split()[1:3] == ["compound_2", "0"] and lines[4].endswith("issues 1")
