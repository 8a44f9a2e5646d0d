"""`docker compose up` for real (tools/compose_check.sh): where a Docker engine answers, the whole stack is built and
run, its MCAP checked from the host, taken down; where none does, the check says why in one line (exit 3)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CHECK = REPO / "tools" / "compose_check.sh"


def _engine() -> str:
    """Why no Docker engine can be used here, or "" when one answers."""
    if shutil.which("docker") is None:
        return "no docker command"
    try:
        info = subprocess.run(["docker", "info"], capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        return "docker info did not answer within 30 s"
    if info.returncode != 0:
        return "no Docker engine answers (docker info: " + (info.stderr.strip().splitlines() or ["?"])[-1] + ")"
    if subprocess.run(["docker", "compose", "version"], capture_output=True, timeout=30).returncode != 0:
        return "no compose v2 plugin"
    return ""


def test_without_an_engine_the_check_says_why_in_one_line(tmp_path: Path) -> None:
    fake = tmp_path / "docker"  # a docker command whose engine does not answer, as on a machine without dockerd
    fake.write_text("#!/bin/sh\necho 'Cannot connect to the Docker daemon at unix:///var/run/docker.sock.' >&2\n"
                    "exit 1\n")
    fake.chmod(0o755)
    env = {**os.environ, "PATH": f"{tmp_path}{os.pathsep}{os.environ['PATH']}"}
    proc = subprocess.run(["bash", str(CHECK)], cwd=REPO, env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 3
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("compose check: cannot run here: no Docker engine answers")
    assert "Cannot connect to the Docker daemon" in lines[0]


def test_compose_up_runs_the_stack_for_real() -> None:
    why = _engine()
    if why:
        pytest.skip(f"needs a Docker engine: {why}")
    proc = subprocess.run(["bash", str(CHECK), "--no-demo"], cwd=REPO, capture_output=True, text=True, timeout=1800)
    if proc.returncode == 3:
        pytest.skip(proc.stdout.strip().splitlines()[-1])
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "complete; down: nothing left running" in proc.stdout and "compose check: passed" in proc.stdout
