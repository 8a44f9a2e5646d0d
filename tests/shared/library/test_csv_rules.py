"""The CSV reader's rules against copies and damage: stray class files, repeated or cut demonstrations, odd numbers,
huge files; the CSV writer's all-or-nothing output; what an .npz read names as its source."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from shared.library import LibraryError, load_library, paper_csv, report_drops, save_library, write_csv_dir
from shared.synthetic import generate_library

from .test_library import make_lib, plausible_demo, write_class


def test_only_numbered_class_files_are_classes(tmp_path):
    """``compound_2 (copy).csv``, ``compound_1.bak.csv`` and ``compound_-1.csv`` were read as three more classes."""
    lib_dir = make_lib(tmp_path / "lib")
    for stray in ("compound_2 (copy).csv", "compound_1.bak.csv", "compound_-1.csv"):
        shutil.copy(lib_dir / "compound_2.csv", lib_dir / stray)
    lib = load_library(lib_dir, report=False)
    assert lib.class_names == ["compound_0", "compound_1", "compound_2"] and lib.counts() == [4, 4, 4]
    unread = sorted(i.reason.split(" not read")[0] for i in lib.issues)
    assert unread == ["compound_-1.csv", "compound_1.bak.csv", "compound_2 (copy).csv"]
    assert all(i.block == -1 and "only those are the library's classes" in i.reason for i in lib.issues)


def test_an_underscore_in_a_number_is_no_digit_separator(tmp_path):
    """``float("1_0")`` is 10: a typo in the index column of row 10 passed as the sample index 10."""
    lib_dir = make_lib(tmp_path / "lib")
    path = lib_dir / "compound_1.csv"
    lines = path.read_text().splitlines()
    assert lines[10].startswith("10,")
    lines[10] = "1_0," + lines[10].split(",", 1)[1]
    path.write_text("\n".join(lines) + "\n")
    lib = load_library(lib_dir, report=False)
    assert lib.counts() == [4, 3, 4]
    (issue,) = lib.issues
    assert (issue.class_name, issue.block) == ("compound_1", 0) and "line 11: non-numeric value '1_0'" in issue.reason


def test_a_file_joined_to_itself_keeps_each_demonstration_once(tmp_path):
    """Joined with ``cat``, each demonstration came twice: held out, its copy in training recognised it."""
    rng = np.random.default_rng(3)
    make_lib(tmp_path / "lib")
    blocks = [plausible_demo(rng) for _ in range(3)]
    write_class(tmp_path / "lib" / "compound_1.csv", blocks + blocks)
    lib = load_library(tmp_path / "lib", report=False)
    assert lib.counts() == [4, 3, 4]
    assert [(i.block, i.reason.split(": ", 1)[1]) for i in lib.issues] == [
        (3 + b, f"the same values as block {b} (lines {40 * b + 1}-{40 * b + 40}): a repeated demonstration, left out")
        for b in range(3)]
    assert "dropped 3 demonstrations (3 kept)" in report_drops(lib)[0]


def test_a_last_demonstration_cut_short_is_kept_and_said(tmp_path):
    """A file cut at a line end kept its last block, 25 of the others' 40 samples, without a word."""
    rng = np.random.default_rng(4)
    make_lib(tmp_path / "lib")
    blocks = [plausible_demo(rng) for _ in range(4)] + [plausible_demo(rng)[:25]]
    write_class(tmp_path / "lib" / "compound_1.csv", blocks)
    lib = load_library(tmp_path / "lib", report=False)
    assert lib.counts() == [4, 5, 4]  # kept: it may be a short demonstration
    (issue,) = lib.issues
    assert issue.block == -1 and issue.reason == ("compound_1.csv: its last demonstration (lines 161-185) has 25 "
                                                  "samples where its other 4 all have 40: the file may have been cut "
                                                  "short (kept)")
    # demonstrations of many lengths: a shorter last one is one of them
    write_class(tmp_path / "lib" / "compound_1.csv", [plausible_demo(rng, t) for t in (40, 45, 35, 30)])
    assert load_library(tmp_path / "lib", report=False).issues == []


def test_a_class_file_over_the_cap_is_one_line(tmp_path, monkeypatch):
    """Parsing holds about 9 times a file's size: a huge file is refused before it is read."""
    monkeypatch.setattr(paper_csv, "MAX_CLASS_FILE_BYTES", 2_000_000)
    make_lib(tmp_path / "lib")
    with open(tmp_path / "lib" / "compound_2.csv", "a") as f:
        f.write("\n" * 2_000_001)
    with pytest.raises(LibraryError) as err:
        load_library(tmp_path / "lib", report=False)
    assert str(err.value) == (f"library file {str(tmp_path / 'lib' / 'compound_2.csv')!r}: 2 MB, over the 2 MB a class "
                              "file may have (reading holds about 9 times its size in memory)")


def test_an_interrupted_csv_write_leaves_the_earlier_library(tmp_path, monkeypatch):
    """Written in place, a write stopped after one file left a mix of two libraries that loaded as valid."""
    out = tmp_path / "lib"
    write_csv_dir(generate_library(3, 4, seed=0), out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    real = np.savetxt
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(args[0])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(np, "savetxt", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_csv_dir(generate_library(3, 4, seed=1), out)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nor a staging directory left behind
    monkeypatch.setattr(np, "savetxt", real)
    write_csv_dir(generate_library(3, 4, seed=1), out)
    assert sorted(p.name for p in out.iterdir()) == sorted(before) and before != {p.name: p.read_bytes()
                                                                                   for p in out.iterdir()}


def test_an_npz_names_itself_and_keeps_its_origin(tmp_path, caplog):
    """A converted library reported the CSV directory it came from as its source, in every message."""
    lib_dir = make_lib(tmp_path / "lib")
    write_class(lib_dir / "compound_0.csv", [plausible_demo(np.random.default_rng(5)) for _ in range(3)]
                + [np.zeros((40, 12))])
    npz = tmp_path / "mylib.npz"
    save_library(load_library(lib_dir, report=False), npz)
    lib = load_library(npz)
    assert (lib.source, lib.origin) == (str(npz), str(lib_dir))
    assert caplog.messages and all(m.startswith(f"library {npz} (class ") for m in caplog.messages)
    assert load_library(lib_dir, report=False).origin == ""


def test_a_format_version_of_another_shape_is_named_so(tmp_path):
    save_library(generate_library(2, 3, seed=0), tmp_path / "a.npz")
    with np.load(tmp_path / "a.npz") as z:
        data = {k: z[k] for k in z.files}
    data["format_version"] = np.array([1])
    np.savez(tmp_path / "b.npz", **data)
    with pytest.raises(LibraryError, match=r": format_version must be a scalar, got shape \(1,\)$"):
        load_library(tmp_path / "b.npz")
    data["format_version"] = np.int64(7)
    np.savez(tmp_path / "c.npz", **data)
    with pytest.raises(LibraryError, match=r": format_version 7, this build reads 1$"):
        load_library(tmp_path / "c.npz")


def test_the_paper_library_reads_as_before(paper_library: Path, tmp_path):
    lib = load_library(paper_library, report=False)
    assert len(lib.demos) == 200 and lib.counts() == [25] * 8 and len(lib.issues) == 1
    write_csv_dir(lib, tmp_path / "copy")
    again = load_library(tmp_path / "copy", report=False)
    assert again.issues == [] and len(again.demos) == 200
    assert all(np.array_equal(a.features, b.features) for a, b in zip(lib.demos, again.demos, strict=True))
