"""The motion-library reader: paper CSV format, validation by rule, native npz, held-out split."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from shared.library import (
    FEATURE_NAMES,
    PLAUSIBLE_RANGES,
    LibraryError,
    LibraryIssue,
    MotionLibrary,
    heldout_split,
    load_library,
    save_library,
    validate_block,
)


def plausible_demo(rng: np.random.Generator, t: int = 40) -> np.ndarray:
    """A smooth (T, 12) motion inside every plausible range."""
    centre = np.array([1.8, 1.7, 0.95, -2.5, 0.1, 0.1, 0.0, 1.6, 0.1, 0.1, 0.05, 0.5])
    s = np.linspace(0, 1, t)[:, None]
    return centre + 0.1 * np.sin(2 * np.pi * (s + rng.uniform(size=12)))


def write_class(path: Path, blocks: list[np.ndarray], index_fn=None) -> None:
    rows = []
    for b in blocks:
        for i, f in enumerate(b):
            idx = index_fn(i) if index_fn else i
            rows.append(",".join([str(idx)] + [repr(float(v)) for v in f]))
    path.write_text("\n".join(rows) + "\n")


def make_lib(tmp_path: Path, n_classes: int = 3, n_demos: int = 4, t: int = 40, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    tmp_path.mkdir(parents=True, exist_ok=True)
    for m in range(n_classes):
        write_class(tmp_path / f"compound_{m}.csv", [plausible_demo(rng, t) for _ in range(n_demos)])
    return tmp_path


def test_feature_names():
    assert len(FEATURE_NAMES) == 12 and set(PLAUSIBLE_RANGES) == set(FEATURE_NAMES)


def test_valid_library(tmp_path):
    lib = load_library(make_lib(tmp_path))
    assert lib.class_names == ["compound_0", "compound_1", "compound_2"]
    assert lib.n_classes == 3 and len(lib.demos) == 12 and lib.issues == []
    assert lib.counts() == [4, 4, 4]
    d = lib.by_class(1)[2]
    assert (d.label, d.index, d.class_name, d.source) == (1, 2, "compound_1", "compound_1.csv#block 2")
    assert d.features.shape == (40, 12) and d.features.dtype == np.float64
    raw = np.loadtxt(tmp_path / "compound_1.csv", delimiter=",")
    np.testing.assert_array_equal(d.features, raw[80:120, 1:])


def test_class_files_sorted_numerically(tmp_path):
    make_lib(tmp_path, n_classes=11, n_demos=1)
    lib = load_library(tmp_path)
    assert lib.class_names[:3] == ["compound_0", "compound_1", "compound_2"] and lib.class_names[10] == "compound_10"


def check_one_issue(tmp_path: Path, bad: str, block: int, pattern: str, n_blocks: int = 4) -> MotionLibrary:
    lib = load_library(tmp_path)
    assert len(lib.issues) == 1, lib.issues
    issue = lib.issues[0]
    assert issue.class_name == bad and issue.block == block
    assert __import__("re").search(pattern, issue.reason), issue.reason
    assert len(lib.by_class(lib.class_names.index(bad))) == n_blocks - 1
    # the valid ones keep consecutive indices
    assert [d.index for d in lib.by_class(lib.class_names.index(bad))] == list(range(n_blocks - 1))
    return lib


def blocks(seed: int = 1, n: int = 4, t: int = 40) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [plausible_demo(rng, t) for _ in range(n)]


def test_shifted_block_like_the_papers_class_6(tmp_path):
    """Columns shifted by one (a 0/25/50/75 value first) and the last four columns zero."""
    make_lib(tmp_path)
    b = blocks()
    shifted = np.zeros_like(b[0])
    shifted[:, 0] = (np.arange(len(shifted)) % 4) * 25
    shifted[:, 1:8] = b[0][:, 0:7]
    b[0] = shifted
    write_class(tmp_path / "compound_2.csv", b)
    check_one_issue(tmp_path, "compound_2", 0, r"lines 1-40: dead channel.*r_shoulder_z.*r_elbow_z.*pelvis_x outside")


def test_nan_block(tmp_path):
    make_lib(tmp_path)
    b = blocks()
    b[2][5, 3] = np.nan
    write_class(tmp_path / "compound_1.csv", b)
    # block 2 starts at line 81; sample 5 is line 86; feature 3 (pelvis_yaw) is column 5 of the CSV
    check_one_issue(tmp_path, "compound_1", 2, r"lines 81-120: line 86: nan in column 5 \(pelvis_yaw\)")


def test_out_of_range_block(tmp_path):
    make_lib(tmp_path)
    b = blocks()
    b[1][10:20, 10] = 0.9  # a 90 cm arm extension
    b[1][14, 10] = 1.2  # the worst of them: on line 55 (block 1 starts at line 41)
    write_class(tmp_path / "compound_0.csv", b)
    check_one_issue(tmp_path, "compound_0", 1, r"r_arm_trans outside its plausible range \[-0.5, 0.5\] m in 10 samples "
                                               r"\(e.g. 1.2 at line 55\)")  # it named no line: 40 to search


def test_wrong_column_count(tmp_path):
    make_lib(tmp_path)
    write_class(tmp_path / "compound_1.csv", blocks())
    lines = (tmp_path / "compound_1.csv").read_text().splitlines()
    lines[45] = lines[45].rsplit(",", 1)[0]  # block 1, sample 5 loses a column
    (tmp_path / "compound_1.csv").write_text("\n".join(lines) + "\n")
    check_one_issue(tmp_path, "compound_1", 1, r"line 46: 12 columns, expected 13")


def test_non_numeric_value(tmp_path):
    make_lib(tmp_path)
    write_class(tmp_path / "compound_1.csv", blocks())
    lines = (tmp_path / "compound_1.csv").read_text().splitlines()
    lines[130] = lines[130].replace(",", ",abc,", 1).rsplit(",", 1)[0]
    (tmp_path / "compound_1.csv").write_text("\n".join(lines) + "\n")
    check_one_issue(tmp_path, "compound_1", 3, r"line 131: non-numeric value 'abc'")


def test_a_bad_value_in_a_demonstrations_first_row_loses_that_demonstration_only(tmp_path):
    """The row still starts its demonstration (its index 0 is read alone): it and the next were merged into the
    one before, 3 demonstrations lost where 1 was bad."""
    make_lib(tmp_path)
    write_class(tmp_path / "compound_1.csv", blocks())
    lines = (tmp_path / "compound_1.csv").read_text().splitlines()
    parts = lines[40].split(",")  # line 41: sample 0 of block 1
    parts[5] = "x"
    lines[40] = ",".join(parts)
    (tmp_path / "compound_1.csv").write_text("\n".join(lines) + "\n")
    check_one_issue(tmp_path, "compound_1", 1, r"lines 41-80: line 41: non-numeric value 'x'")


@pytest.mark.parametrize("prefix", ["\ufeff", "index,pelvis_x,pelvis_y\n", "\ufeffidx,a,b,c\n"])
def test_a_byte_order_mark_or_a_header_line_is_no_demonstration(tmp_path, prefix):
    make_lib(tmp_path)
    path = tmp_path / "compound_1.csv"
    path.write_text(prefix + path.read_text(), encoding="utf-8")
    lib = load_library(tmp_path)
    assert lib.issues == [] and lib.counts() == [4, 4, 4]


def test_index_gap(tmp_path):
    make_lib(tmp_path)
    write_class(tmp_path / "compound_0.csv", blocks())
    lines = (tmp_path / "compound_0.csv").read_text().splitlines()
    del lines[50]  # block 1 jumps from sample 9 to 11
    (tmp_path / "compound_0.csv").write_text("\n".join(lines) + "\n")
    check_one_issue(tmp_path, "compound_0", 1, r"line 51: sample index 11 where 10 was expected")


def test_truncated_and_too_short_blocks(tmp_path):
    make_lib(tmp_path)
    b = blocks()
    b[3] = b[3][:15]
    write_class(tmp_path / "compound_0.csv", b)
    check_one_issue(tmp_path, "compound_0", 3, r"truncated: 15 samples")
    b = blocks(t=8, n=4)
    write_class(tmp_path / "compound_0.csv", b)
    lib = load_library(tmp_path)
    assert [i.block for i in lib.issues] == [0, 1, 2, 3, -1]
    assert "fewer than the minimum" in lib.issues[0].reason and "no valid demonstration" in lib.issues[-1].reason


def test_file_not_starting_at_zero(tmp_path):
    make_lib(tmp_path)
    write_class(tmp_path / "compound_0.csv", blocks(), index_fn=lambda i: i + 1)
    lib = load_library(tmp_path)
    assert len(lib.by_class(0)) == 0 and lib.issues[0].block == 0
    assert "sample index 1 where 0 was expected" in lib.issues[0].reason


def test_subnormal_garbage(tmp_path):
    f = blocks()[0]
    f[3, 4] = 2.4e-322
    assert any("subnormal" in r for r in validate_block(f))
    assert validate_block(blocks()[0]) == []


def test_missing_paths(tmp_path):
    with pytest.raises(LibraryError, match=r"^library '.*nowhere' not found$"):
        load_library(tmp_path / "nowhere")
    with pytest.raises(LibraryError, match="holds no .csv class files"):
        load_library(tmp_path)
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(LibraryError, match="neither a directory"):
        load_library(tmp_path / "x.txt")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(LibraryError, match=r"bad.npz.*not an npz archive \(a zip file\); it starts with b'not '"):
        load_library(tmp_path / "bad.npz")
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(LibraryError, match="not an npz archive .*; the file is empty"):
        load_library(tmp_path / "empty.npz")
    (tmp_path / "cut.npz").write_bytes(b"PK\x03\x04" + bytes(40))  # a zip cut short: numpy's error, named
    with pytest.raises(LibraryError, match="cut.npz.*unreadable npz"):
        load_library(tmp_path / "cut.npz")
    (tmp_path / "text.npz").write_text("# the README, saved under the library's name\n")
    with pytest.raises(LibraryError, match="not an npz archive") as exc:  # numpy would advise allow_pickle
        load_library(tmp_path / "text.npz")
    assert "pickle" not in str(exc.value)
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(LibraryError, match="not a Foresight library npz"):
        load_library(tmp_path / "other.npz")
    np.savez(tmp_path / "model.npz", format=np.array("foresight-prediction-model"), means=np.zeros(3))
    with pytest.raises(LibraryError, match="model.npz': a 'foresight-prediction-model' file, not a motion library"):
        load_library(tmp_path / "model.npz")  # `foresight train`'s output given for its input: ten missing keys


def test_npz_round_trip(tmp_path):
    make_lib(tmp_path / "csv")
    b = blocks()
    b[1][0, 0] = np.inf
    write_class(tmp_path / "csv" / "compound_1.csv", b)
    lib = load_library(tmp_path / "csv")
    save_library(lib, tmp_path / "out" / "lib.npz")
    with np.load(tmp_path / "out" / "lib.npz", allow_pickle=False) as z:
        assert all(z[k].dtype != object for k in z.files)
    back = load_library(tmp_path / "out" / "lib.npz")
    assert back.class_names == lib.class_names and back.issues == lib.issues
    assert (back.source, back.origin) == (str(tmp_path / "out" / "lib.npz"), lib.source)  # the file read, and whence
    assert len(back.demos) == len(lib.demos) == 11
    for a, b2 in zip(lib.demos, back.demos, strict=True):
        assert (a.label, a.index, a.class_name, a.source) == (b2.label, b2.index, b2.class_name, b2.source)
        np.testing.assert_array_equal(a.features, b2.features)


def test_heldout_split(tmp_path):
    lib = load_library(make_lib(tmp_path, n_demos=6))
    train, held = heldout_split(lib, 2, seed=3)
    assert len(held) == 6 and len(train) == 12
    assert {(d.label, d.index) for d in train}.isdisjoint({(d.label, d.index) for d in held})
    assert [sum(d.label == m for d in held) for m in range(3)] == [2, 2, 2]
    again = heldout_split(lib, 2, seed=3)
    assert [(d.label, d.index) for d in again[1]] == [(d.label, d.index) for d in held]
    other = heldout_split(lib, 2, seed=4)[1]
    assert [(d.label, d.index) for d in other] != [(d.label, d.index) for d in held]
    assert heldout_split(lib, 0, seed=0) == (lib.demos, [])
    with pytest.raises(LibraryError, match="cannot hold out 6"):
        heldout_split(lib, 6, seed=0)
    with pytest.raises(LibraryError, match="the seed must be an integer >= 0, got -1"):  # numpy's error, a traceback
        heldout_split(lib, 1, seed=-1)


def test_issue_str():
    assert str(LibraryIssue("c", 2, "why")) == "c block 2: why"
    assert str(LibraryIssue("c", -1, "why")) == "c whole file: why"


def test_paper_library(paper_library, tmp_path):
    lib = load_library(paper_library)
    assert lib.n_classes == 8 and len(lib.demos) == 200 and lib.counts() == [25] * 8
    assert all(d.n_samples == 100 for d in lib.demos)
    assert len(lib.issues) == 1
    issue = lib.issues[0]
    assert (issue.class_name, issue.block) == ("compound_6", 0)
    assert "dead channel" in issue.reason
    assert lib.by_class(6)[0].source == "compound_6.csv#block 1"
    save_library(lib, tmp_path / "paper.npz")
    back = load_library(tmp_path / "paper.npz")
    assert back.counts() == [25] * 8 and back.issues == lib.issues


@pytest.mark.parametrize(("key", "value", "match"), [
    (None, None, "one array, not a Foresight library npz"),
    ("format_version", np.array([1, 1]), r"format_version must be a scalar, got shape \(2,\)"),
    ("format_version", np.array(1.9), "format_version must be an integer, got float64 1.9"),  # it read as 1
    ("class_names", np.array(["a", "a"]), "class_names must be unique"),
    ("demo_index", "zeros", "two demonstrations have the same class and index"),
    ("issue_reason", np.array(["r", "s", "t"]), "lengths differ"),
    ("demo_length", "float", "demo_length must hold integers"),
    ("class_names", np.array("compound_0"), "class_names must be a list"),
    ("issue_block", np.array(["x"]), "issue_block must hold integers"),
])
def test_a_malformed_npz_is_a_library_error(tmp_path, key, value, match):
    """Each of these was a TypeError or ValueError traceback (a 0-d class_names: single-letter classes)."""
    make_lib(tmp_path / "csv")
    save_library(load_library(tmp_path / "csv"), tmp_path / "l.npz")
    with np.load(tmp_path / "l.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    bad = tmp_path / "bad.npz"
    if key is None:
        with bad.open("wb") as f:
            np.save(f, arrays["features"])
    else:
        arrays[key] = (np.zeros_like(arrays[key]) if value == "zeros" else arrays[key].astype(np.float64)) \
            if isinstance(value, str) else value
        if key == "issue_block":
            arrays["issue_class"], arrays["issue_reason"] = np.array(["compound_0"]), np.array(["r"])
        np.savez(bad, **arrays)
    with pytest.raises(LibraryError, match=rf"library file '.*bad\.npz'.*{match}"):
        load_library(bad)


def test_an_npz_of_other_number_kinds_is_read_or_refused_by_its_kind(tmp_path):
    """Complex features (imaginary part 5) loaded as valid demonstrations with a ComplexWarning, strings were parsed
    as numbers, and a uint64 demo_length turned the offsets into floats ("inconsistent (TypeError: slice ...")."""
    make_lib(tmp_path / "csv")
    lib = load_library(tmp_path / "csv")
    save_library(lib, tmp_path / "l.npz")
    with np.load(tmp_path / "l.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for kind, features in (("complex128", arrays["features"] + 5j), ("<U32", arrays["features"].astype(str))):
        np.savez(tmp_path / "bad.npz", **{**arrays, "features": features})
        with pytest.raises(LibraryError, match=rf"bad\.npz'.*: features must hold numbers, got {re.escape(kind)}"):
            load_library(tmp_path / "bad.npz")
    unsigned = {k: arrays[k].astype(np.uint64) for k in ("demo_length", "demo_label", "demo_index")}
    np.savez(tmp_path / "u.npz", **{**arrays, **unsigned})
    back = load_library(tmp_path / "u.npz")
    assert [d.features.tolist() for d in back.demos] == [d.features.tolist() for d in lib.demos]


def test_a_bad_demonstration_in_an_npz_is_numbered_within_its_class(tmp_path):
    make_lib(tmp_path / "csv")
    save_library(load_library(tmp_path / "csv"), tmp_path / "l.npz")
    with np.load(tmp_path / "l.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    start = int(arrays["demo_length"][:6].sum())  # class 1's third demonstration (4 per class)
    arrays["features"][start + 2, 3] = np.nan
    np.savez(tmp_path / "edited.npz", **arrays)
    lib = load_library(tmp_path / "edited.npz")
    assert [(i.class_name, i.block) for i in lib.issues] == [("compound_1", 2)]
    assert lib.issues[0].reason.startswith("edited.npz: npz demonstration 2 of compound_1: ")


@pytest.mark.parametrize("names, match", [(["a" * 257, "b"], "has 257 characters"), (["", "b"], "has 0 characters"),
                                          ([f"c{i}" for i in range(257)], "257 classes, over the wire's limit")])
def test_a_library_whose_classes_could_not_be_published_is_refused(tmp_path, names, match):
    lib = load_library(make_lib(tmp_path / "csv"))  # the predictor would train on it, then fail every posterior
    lib.class_names = names
    lib.demos = [d for d in lib.demos if d.label < len(names)]
    save_library(lib, tmp_path / "lib.npz")
    with pytest.raises(LibraryError, match=match):
        load_library(tmp_path / "lib.npz")


def test_save_library_replaces_a_library_only_with_a_whole_one(tmp_path, monkeypatch):
    """A write that fails (a full disk, Ctrl-C) leaves the earlier library readable and no temporary file."""
    from shared.library import npz
    from shared.synthetic import generate_library

    path = tmp_path / "lib.npz"
    save_library(generate_library(2, 1, seed=0), path)

    def interrupted(f, **arrays):
        f.write(b"PK\x03\x04 half a zip")
        raise KeyboardInterrupt
    monkeypatch.setattr(npz.np, "savez_compressed", interrupted)
    with pytest.raises(KeyboardInterrupt):
        save_library(generate_library(3, 1, seed=1), path)
    assert load_library(path).n_classes == 2
    assert [p.name for p in tmp_path.iterdir()] == ["lib.npz"]
    monkeypatch.undo()
    save_library(generate_library(3, 1, seed=1), tmp_path / "noext")
    assert load_library(tmp_path / "noext.npz").n_classes == 3


@pytest.mark.parametrize("edit", ["empty fields at the end", "empty fields between blocks", "header again",
                                  "trailing commas", "numbered header"])
def test_a_spreadsheets_export_quirks_cost_no_demonstration(tmp_path, edit):
    """Rows of empty fields and a repeated header were taken for rows of the demonstration before them, which was
    dropped; a comma at the end of every line made 13 features and dropped every block; pandas' numbered header
    was a one-row demonstration."""
    make_lib(tmp_path)
    path = tmp_path / "compound_1.csv"
    lines = path.read_text().splitlines()
    width = lines[0].count(",")
    if edit == "empty fields at the end":
        lines += ["," * width] * 2
    elif edit == "empty fields between blocks":
        lines.insert(40, "," * width)
    elif edit == "header again":
        lines = ["index," + ",".join(FEATURE_NAMES)] + lines[:40] + ["index," + ",".join(FEATURE_NAMES)] + lines[40:]
    elif edit == "trailing commas":
        lines = [line + "," for line in lines]
    else:
        lines.insert(0, ",".join(str(i) for i in range(width + 1)))
    path.write_text("\n".join(lines) + "\n")
    lib = load_library(tmp_path)
    assert lib.issues == [] and lib.counts() == [4, 4, 4] and lib.n_features == 12


def test_a_damaged_npz_is_a_library_error_not_a_traceback(tmp_path):
    """Damage inside a compressed member raised zlib.error from numpy's lazy read: every command's traceback."""
    import zipfile

    from shared.synthetic import generate_library

    save_library(generate_library(3, 4, seed=0), tmp_path / "lib.npz")
    raw = bytearray((tmp_path / "lib.npz").read_bytes())
    with zipfile.ZipFile(tmp_path / "lib.npz") as z:
        info = z.getinfo("features.npy")
    for offset in (100, 200, 400):  # some damage fails the member's CRC, some the deflate stream (zlib.error)
        bad = bytearray(raw)
        at = info.header_offset + 30 + len(info.filename) + len(info.extra) + offset
        bad[at:at + 40] = bytes([0xFF]) * 40
        (tmp_path / "bad.npz").write_bytes(bytes(bad))
        with pytest.raises(LibraryError, match="unreadable npz"):
            load_library(tmp_path / "bad.npz")


def test_a_csv_copy_keeps_every_float64(tmp_path):
    """%.9g rounded the features: a CSV and an npz of the same library differed by up to 5e-9."""
    from shared.library import write_csv_dir
    from shared.synthetic import generate_library

    lib = generate_library(2, 3, seed=5)
    write_csv_dir(lib, tmp_path)
    back = load_library(tmp_path)
    for a, b in zip(lib.demos, back.demos, strict=True):
        np.testing.assert_array_equal(a.features, b.features)


def test_files_a_class_directory_does_not_read_and_missing_numbers_are_said(tmp_path):
    """A .csv beside compound_<m>.csv files was left out, and a missing compound_1.csv renumbered the classes (class 1
    became compound_2), both without a word (a review's first hour)."""
    from shared.library.report import drop_lines

    make_lib(tmp_path, n_classes=3, n_demos=4)
    (tmp_path / "compound_1.csv").rename(tmp_path / "reach_a.csv")
    lib = load_library(tmp_path)
    assert lib.class_names == ["compound_0", "compound_2"]
    lines = drop_lines(lib)
    assert any("reach_a.csv: reach_a.csv not read" in ln for ln in lines), lines
    assert any("compound_1.csv missing: the classes are numbered in their files' order (class 1 is compound_2)" in ln
               for ln in lines), lines
    assert len(lib.demos) == 2 * 4  # the two classes still read


def test_odd_class_numbers_are_said_with_the_classes_they_became(tmp_path):
    """compound_0.csv beside compound_00.csv and compound_2.csv: the line said class 1 was compound_2 (it is class 2;
    compound_00 is class 1), from the files' positions among the numbers instead of among the classes."""
    from shared.library.report import drop_lines

    make_lib(tmp_path, n_classes=3, n_demos=2)
    (tmp_path / "compound_1.csv").rename(tmp_path / "compound_00.csv")
    lib = load_library(tmp_path)
    assert lib.class_names == ["compound_0", "compound_00", "compound_2"]
    lines = drop_lines(lib)
    assert any("compound_0.csv and compound_00.csv have the same number 0: both read, as classes 0, 1" in ln
               for ln in lines), lines
    assert any("compound_1.csv missing: the classes are numbered in their files' order (class 2 is compound_2)" in ln
               for ln in lines), lines


def test_a_relative_path_not_found_names_the_directory_it_was_read_from(tmp_path, monkeypatch):
    """A config file's library = 'small.npz' is read from the working directory, not the file's: a service started
    elsewhere said only "library 'small.npz' not found"."""
    from services.predictor.model import ModelError, PredictionModel
    from shared.config import ConfigError, load_toml

    monkeypatch.chdir(tmp_path)
    where = re.escape(f"not found (relative to the working directory {tmp_path})")
    with pytest.raises(LibraryError, match=rf"^library 'small.npz' {where}$"):
        load_library("small.npz")
    with pytest.raises(ConfigError, match=rf"^config file 'c.toml' {where}$"):
        load_toml("c.toml")
    with pytest.raises(ModelError, match=rf"^model file 'm.npz' {where}; run"):
        PredictionModel.load("m.npz")
    with pytest.raises(LibraryError, match=r"^library '/nowhere/small.npz' not found$"):  # absolute: said as given
        load_library("/nowhere/small.npz")
