"""What reading a library dropped, said once: one line per file, and once per command that reads it often."""

from __future__ import annotations

import logging
from pathlib import Path

from shared.library import load_library, write_csv_dir
from shared.library.report import said_once
from shared.synthetic import generate_library


def broken_library(directory: Path) -> Path:
    """A paper-format library of 2 classes x 3 demonstrations whose compound_1.csv has a NaN in its first row."""
    write_csv_dir(generate_library(2, 3, seed=5), directory)
    path = directory / "compound_1.csv"
    lines = path.read_text().splitlines()
    fields = lines[0].split(",")
    fields[7] = "nan"
    lines[0] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    return directory


def _drops(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]


def test_each_read_says_what_it_dropped(tmp_path, caplog):
    lib = broken_library(tmp_path / "lib")
    caplog.set_level(logging.WARNING)
    load_library(lib)
    load_library(lib)
    assert len(_drops(caplog)) == 2 and "compound_1.csv: dropped 1 demonstration (2 kept): block 0" in _drops(caplog)[0]


def test_within_said_once_a_line_is_said_once_and_a_line_said_elsewhere_not_at_all(tmp_path, caplog):
    a, b = broken_library(tmp_path / "a"), broken_library(tmp_path / "b")
    caplog.set_level(logging.WARNING)
    load_library(a)
    said = _drops(caplog)
    caplog.clear()
    with said_once(said):
        for _ in range(3):
            load_library(a)  # said before the block: never again
            load_library(b)  # new: once
    assert len(_drops(caplog)) == 1 and str(b / "compound_1.csv") in _drops(caplog)[0]
    caplog.clear()
    load_library(a)  # the block is left: every read says it again
    assert len(_drops(caplog)) == 1
