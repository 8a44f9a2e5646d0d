"""Broken library files through the replayer's path: the loader's rules apply and what they drop is said
once, one line per file (issue 12)."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest

from services.processes import free_port
from services.replayer.core import ReplayerConfig
from services.replayer.service import ReplayerService
from shared.config import ZenohConfig
from shared.library import write_csv_dir
from shared.synthetic import generate_library

REPO = Path(__file__).resolve().parents[3]


def _break(path: Path, line: int, how: str) -> None:
    """Corrupt one 1-based ``line`` of a CSV file: a NaN in column 8, or one extra column."""
    lines = path.read_text().splitlines()
    fields = lines[line - 1].split(",")
    if how == "nan":
        fields[7] = "nan"
    else:
        fields.append("0.5")
    lines[line - 1] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def clean_lib(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """A paper-format library of 2 classes x 3 demonstrations; returns (dir, samples of one demonstration)."""
    lib = generate_library(2, 3, seed=5)
    out = tmp_path_factory.mktemp("clean")
    write_csv_dir(lib, out)
    return out, lib.demos[0].n_samples


def _copy(src: Path, dst: Path) -> Path:
    dst.mkdir()
    for f in src.glob("*.csv"):
        (dst / f.name).write_text(f.read_text())
    return dst


@pytest.mark.parametrize("how, expected", [
    ("nan", "nan in column 8 (torso_z)"),
    ("extra", "14 columns, expected 13 (sample index + 12 features)"),
])
def test_replayer_drops_a_broken_demonstration_and_says_so_once(clean_lib, tmp_path, caplog, how, expected):
    src, n = clean_lib
    lib_dir = _copy(src, tmp_path / how)
    line = n + 7  # in the second demonstration (block 1) of compound_1
    _break(lib_dir / "compound_1.csv", line, how)
    caplog.set_level(logging.WARNING)
    service = ReplayerService(ReplayerConfig(library=lib_dir), ZenohConfig(connect=[]))
    drops = [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]
    assert drops == [f"library {lib_dir / 'compound_1.csv'}: dropped 1 demonstration (2 kept): block 1 "
                     f"(lines {n + 1}-{2 * n}: line {line}: {expected})"]
    assert len(service.demos) == 5 and all(d.source != "compound_1.csv#block 1" for d in service.demos)


def test_replayer_process_reports_each_broken_file_on_one_line(clean_lib, tmp_path):
    src, n = clean_lib
    lib_dir = _copy(src, tmp_path / "both")
    _break(lib_dir / "compound_0.csv", 3, "nan")
    _break(lib_dir / "compound_1.csv", 2 * n + 4, "extra")
    cmd = [sys.executable, "-m", "services.replayer", "--library", str(lib_dir), "--rate-hz", "1000",
           "--max-demos", "1", "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{free_port()}"]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    drops = [ln for ln in done.stderr.splitlines() if "dropped" in ln]
    assert len(drops) == 2, done.stderr[-2000:]
    assert "compound_0.csv: dropped 1 demonstration (2 kept): block 0 (lines 1-" in drops[0]
    assert "line 3: nan in column 8 (torso_z)" in drops[0]
    assert f"compound_1.csv: dropped 1 demonstration (2 kept): block 2 (lines {2 * n + 1}-" in drops[1]
    assert f"line {2 * n + 4}: 14 columns" in drops[1]
    assert "4 demonstrations selected" in done.stderr
