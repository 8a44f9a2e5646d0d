"""tools/cpus.py: the CPUs `make test` sizes its workers by, quota included."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tools.cpus import quota_cpus, usable_cpus

REPO = Path(__file__).resolve().parents[2]


def _affinity() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@pytest.mark.parametrize(("files", "quota"), [
    ({"cpu.max": "max 100000\n"}, None),
    ({"cpu.max": "150000 100000\n"}, 1.5),
    ({"cpu/cpu.cfs_quota_us": "-1\n", "cpu/cpu.cfs_period_us": "100000\n"}, None),
    ({"cpu/cpu.cfs_quota_us": "50000\n", "cpu/cpu.cfs_period_us": "100000\n"}, 0.5),
    ({"cpu.max": "garbage\n"}, None),
    ({}, None),
])
def test_quota_from_cgroup_v2_or_v1(tmp_path: Path, files: dict[str, str], quota: float | None) -> None:
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert quota_cpus(tmp_path) == quota


def test_the_quota_caps_the_affinity(tmp_path: Path) -> None:
    (tmp_path / "cpu.max").write_text("100000 100000\n")
    assert usable_cpus(tmp_path) == 1
    (tmp_path / "cpu.max").write_text("10000 100000\n")  # a tenth of a CPU: still one worker
    assert usable_cpus(tmp_path) == 1
    (tmp_path / "cpu.max").write_text("max 100000\n")
    assert usable_cpus(tmp_path) == _affinity()


def test_runs_without_the_package_as_make_runs_it() -> None:
    out = subprocess.run([sys.executable, "-I", str(REPO / "tools" / "cpus.py"), "--max", "1"], capture_output=True,
                         text=True, timeout=30, check=True)
    assert out.stdout == "1\n"


def test_a_negative_cap_is_refused() -> None:
    """--max -3 printed every CPU, as for no cap."""
    out = subprocess.run([sys.executable, "-I", str(REPO / "tools" / "cpus.py"), "--max", "-3"], capture_output=True,
                         text=True, timeout=30)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.splitlines()[-1] == "python tools/cpus.py: error: --max: must be 0 (no cap) or more, got -3"
