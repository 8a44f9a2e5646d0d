"""``foresight library``: info, validate, convert and generate, with one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shared.library import load_library, write_csv_dir
from shared.synthetic import generate_library
from shared.synthetic_wide import WIDE_FEATURE_NAMES, generate_wide_library
from tools.library import main as library_main


@pytest.fixture(scope="module")
def wide():
    return generate_wide_library(n_classes=4, n_demos=5, seed=1)


def make_lib(directory: Path) -> Path:
    """3 classes of 4 valid demonstrations in the paper's CSV format."""
    write_csv_dir(generate_library(3, 4, seed=0), directory)
    return directory


def kill_last_feature_of_first_block(path: Path) -> None:
    """Zero the last feature (r_elbow_z) of the file's first demonstration: a dead channel."""
    rows = np.loadtxt(path, delimiter=",")
    first = np.flatnonzero(rows[:, 0] == 0)[1]
    rows[:first, -1] = 0.0
    np.savetxt(path, rows, delimiter=",", fmt=["%d"] + ["%.9g"] * (rows.shape[1] - 1))


def test_cli(tmp_path, capsys):
    make_lib(tmp_path / "csv")
    assert library_main(["info", str(tmp_path / "csv")]) == 0
    out = capsys.readouterr().out
    assert "classes: 3, valid demonstrations: 12, issues: 0" in out
    assert library_main(["validate", str(tmp_path / "csv")]) == 0
    assert library_main(["convert", str(tmp_path / "csv"), "--out", str(tmp_path / "l.npz")]) == 0
    assert load_library(tmp_path / "l.npz").counts() == [4, 4, 4]
    kill_last_feature_of_first_block(tmp_path / "csv" / "compound_0.csv")
    assert library_main(["validate", str(tmp_path / "csv")]) == 1
    out = capsys.readouterr().out
    assert "issue: compound_0 block 0:" in out and "dead channel(s): r_elbow_z" in out
    with pytest.raises(SystemExit) as e:
        library_main(["info", str(tmp_path / "missing")])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "missing' not found" in err
    with pytest.raises(SystemExit) as e:
        library_main(["convert", str(tmp_path / "csv"), "--out", str(tmp_path / "l.txt")])
    assert e.value.code == 2


def test_info_of_a_16_feature_csv(wide, tmp_path, capsys) -> None:
    write_csv_dir(wide, tmp_path / "w")
    assert library_main(["info", str(tmp_path / "w")]) == 0
    out = capsys.readouterr().out
    assert "features: 16 (feature_1 .. feature_16; no mapping to the human model" in out
    assert "issue" not in out.replace("issues", "")


def test_info_names_a_file_of_another_column_count_once(wide, tmp_path, capsys) -> None:
    write_csv_dir(generate_library(4, 5, seed=2), tmp_path / "mixed")
    write_csv_dir(wide, tmp_path / "w")
    (tmp_path / "mixed" / "compound_2.csv").write_bytes((tmp_path / "w" / "compound_2.csv").read_bytes())
    assert library_main(["info", str(tmp_path / "mixed")]) == 0
    out = capsys.readouterr().out.splitlines()
    about_2 = [line for line in out if "compound_2" in line]
    assert len(about_2) == 2  # its row in the class table and its one issue line
    assert not any("line 1:" in line or "line 2:" in line for line in out)


def test_cli_generate_npz_and_csv(tmp_path, capsys) -> None:
    npz = tmp_path / "syn.npz"
    assert library_main(["generate", "--classes", "3", "--demos", "4", "--seed", "2", "--out", str(npz)]) == 0
    csv_dir = tmp_path / "csv"
    assert library_main(["generate", "--classes", "3", "--demos", "4", "--seed", "2", "--out", str(csv_dir)]) == 0
    a, b = load_library(npz), load_library(csv_dir)
    assert a.class_names == ["blue_cup", "red_cup", "near_left"] and a.n_classes == b.n_classes == 3
    for x, y in zip(a.demos, b.demos, strict=True):
        np.testing.assert_allclose(x.features, y.features, rtol=1e-8, atol=1e-9)
    direct = generate_library(3, 4, seed=2)
    np.testing.assert_array_equal(a.demos[5].features, direct.demos[5].features)
    out = capsys.readouterr().out
    # a CSV directory names its classes by file: say so (it printed the goal names, as if they were kept)
    assert "(compound_0, compound_1, compound_2, as a CSV directory names its classes: blue_cup, red_cup, " \
           "near_left in that order; an .npz keeps the names)" in out
    assert b.class_names == ["compound_0", "compound_1", "compound_2"]
    with pytest.raises(SystemExit):
        library_main(["generate", "--classes", "12", "--out", str(tmp_path / "x.npz")])


def test_generate_writes_no_library_that_no_command_could_read(tmp_path, capsys) -> None:
    """A layout's goal named "" was generated and written; every later read refused it."""
    layout = tmp_path / "layout.toml"
    layout.write_text('name = "bad"\nscene = "pr2_two_cups"\n[[goals]]\nname = ""\nposition = [0.4, -0.3, 0.0]\n'
                      '[[goals]]\nname = "b"\nposition = [0.4, -0.1, 0.0]\n')
    with pytest.raises(SystemExit) as e:
        library_main(["generate", "--classes", "2", "--demos", "3", "--layout", str(layout), "--out",
                      str(tmp_path / "bad.npz")])
    assert e.value.code == 2 and "class name '' has 0 characters" in capsys.readouterr().err
    assert not (tmp_path / "bad.npz").exists()


def test_generate_cli_wide(tmp_path, capsys) -> None:
    assert library_main(["generate", "--feature-set", "wide16", "--classes", "4", "--demos", "3",
                         "--out", str(tmp_path / "w.npz")]) == 0
    assert "100 samples of 16 features each" in capsys.readouterr().out
    assert load_library(tmp_path / "w.npz").feature_names == WIDE_FEATURE_NAMES
    with pytest.raises(SystemExit) as exc:
        library_main(["generate", "--feature-set", "wide16", "--classes", "2", "--demos", "2",
                      "--out", str(tmp_path / "x.npz"), "--plot", str(tmp_path / "p.png")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--plot (hand positions in the scene) needs a mapping" in err[0]


def test_cli_to_and_from_keypoints(tmp_path, capsys) -> None:
    from shared.library import save_library

    lib = tmp_path / "lib.npz"
    save_library(generate_library(4, 1, seed=2), lib)  # classes not in sorted order: blue, red, near_left, far_left
    assert library_main(["to-keypoints", str(lib), "--out", str(tmp_path / "kp"), "--noise-m", "0.01"]) == 0
    assert sorted(p.name for p in (tmp_path / "kp").glob("*.csv")) == [f"{c}.csv" for c in
                                                                       sorted(load_library(lib).class_names)]
    assert library_main(["from-keypoints", str(tmp_path / "kp"), "--out", str(tmp_path / "back.npz")]) == 0
    out = capsys.readouterr().out
    back = load_library(tmp_path / "back.npz")
    assert "fit residual median" in out and len(back.demos) == 4
    assert back.class_names == load_library(lib).class_names  # the labels' order survives (it was sorted by name)
    assert [d.label for d in back.demos] == [d.label for d in load_library(lib).demos]
    (tmp_path / "kp" / "classes.txt").write_text("red_cup\nnot_a_class\n")
    with pytest.raises(SystemExit):
        library_main(["from-keypoints", str(tmp_path / "kp"), "--out", str(tmp_path / "bad.npz")])
    assert "classes.txt: lists red_cup, not_a_class, but the CSV files are" in capsys.readouterr().err
    for argv, text in ((["to-keypoints", str(lib), "--out", str(tmp_path / "x"), "--drop", "1.5"], "--drop"),
                       (["from-keypoints", str(tmp_path / "none"), "--out", str(tmp_path / "y.npz")],
                        "not a directory")):
        with pytest.raises(SystemExit) as exc:
            library_main(argv)
        assert exc.value.code == 2 and text in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["generate", "--seed", "-1", "--out", "{d}/l.npz"],
                                  ["generate", "--out", "{d}/adir.npz"],
                                  ["generate", "--out", "{d}/afile/l.npz"]])
def test_generate_bad_seed_or_output_is_one_line(tmp_path, capsys, argv) -> None:
    """A negative seed was a numpy traceback; an output that is a directory or under a file an OSError traceback."""
    (tmp_path / "afile").write_text("")
    (tmp_path / "adir.npz").mkdir()
    with pytest.raises(SystemExit) as e:
        library_main([a.replace("{d}", str(tmp_path)) for a in argv])
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and err.count("\n") == 0 and err, err


def test_an_output_directory_is_the_librarys_own(tmp_path, capsys) -> None:
    """A smaller library written where a larger one was leaves none of the larger one's classes behind."""
    out = tmp_path / "lib"
    assert library_main(["generate", "--classes", "3", "--demos", "1", "--out", str(out)]) == 0
    assert library_main(["generate", "--classes", "2", "--demos", "1", "--out", str(out)]) == 0
    assert "removed 1 file(s) of an earlier library: compound_2.csv" in capsys.readouterr().out
    assert load_library(out).n_classes == 2
    kp = tmp_path / "kp"
    assert library_main(["to-keypoints", str(tmp_path / "lib"), "--out", str(kp)]) == 0
    (kp / "an_old_class.csv").write_text("demo,frame\n")
    assert library_main(["to-keypoints", str(tmp_path / "lib"), "--out", str(kp)]) == 0
    assert "removed 1 file(s) of an earlier library: an_old_class.csv" in capsys.readouterr().out
    assert len(list(kp.glob("*.csv"))) == 2 and (kp / "classes.txt").read_text().count("\n") == 2


def test_to_keypoints_refuses_before_writing(wide, tmp_path, capsys) -> None:
    """A 16-feature library used to leave a header-only CSV behind; infinite noise wrote a library of inf."""
    write_csv_dir(wide, tmp_path / "wide")
    wide = tmp_path / "wide"
    for argv, text in (([str(wide), "--out", str(tmp_path / "kp")], "needs a mapping"),
                       ([str(wide), "--out", str(tmp_path / "kp"), "--noise-m", "inf"], "--noise-m"),
                       ([str(wide), "--out", ""], "--out: empty")):
        with pytest.raises(SystemExit) as exc:
            library_main(["to-keypoints", *argv])
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 2 and err.count("\n") == 0 and text in err, err
    assert not (tmp_path / "kp").exists()


@pytest.mark.parametrize("plot, text", [("top.txt", "ending in .png"), ("top", "ending in .png"),
                                        ("", "--plot: empty")])
def test_generate_refuses_a_plot_it_could_not_write_before_writing_the_library(tmp_path, capsys, plot, text):
    with pytest.raises(SystemExit) as exc:
        library_main(["generate", "--classes", "1", "--demos", "1", "--out", str(tmp_path / "l.npz"),
                      "--plot", str(tmp_path / plot) if plot else ""])
    assert exc.value.code == 2 and text in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [["info", ""], ["validate", " "], ["generate", "--out", ""],
                                  ["convert", "x", "--out", ""]])
def test_an_empty_path_is_not_the_current_directory(tmp_path, monkeypatch, capsys, argv) -> None:
    monkeypatch.chdir(tmp_path)
    write_csv_dir(generate_library(1, 1, seed=0), tmp_path)  # what an empty path used to read (or scatter over)
    with pytest.raises(SystemExit) as exc:
        library_main(argv)
    assert exc.value.code == 2 and "empty" in capsys.readouterr().err


def test_convert_refuses_a_library_without_a_valid_demonstration(tmp_path, capsys) -> None:
    d = tmp_path / "bad"
    d.mkdir()
    (d / "compound_0.csv").write_text("0," + ",".join(["nan"] * 12) + "\n")
    with pytest.raises(SystemExit) as exc:
        library_main(["convert", str(d), "--out", str(tmp_path / "out.npz")])
    assert exc.value.code == 2 and "no valid demonstration, nothing to convert" in capsys.readouterr().err
    assert not (tmp_path / "out.npz").exists()


def test_a_file_in_the_way_of_the_output_is_named(tmp_path, capsys) -> None:
    (tmp_path / "afile").write_text("")
    for argv in (["generate", "--classes", "1", "--demos", "1", "--out", str(tmp_path / "afile" / "sub" / "l.npz")],
                 ["generate", "--classes", "1", "--demos", "1", "--out", str(tmp_path / "afile" / "dir")]):
        with pytest.raises(SystemExit):
            library_main(argv)
        assert f"{tmp_path / 'afile'}: a file is in the way" in capsys.readouterr().err
