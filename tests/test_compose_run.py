"""`docker compose up` for real (tools/compose_check.sh): where a Docker engine answers, the whole stack is built and
run, its MCAP checked from the host, taken down; where none does, the check says why in one line (exit 3)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
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


def test_the_secure_checks_certificates_are_outside_every_mounted_directory(tmp_path: Path) -> None:
    """`--secure` made the CA and every role's key in runs/compose-check/security, and runs/ is mounted into every
    container: each could read ca.key and every other role's key. They are now made outside the clone (only each
    role's own files are mounted, by compose.secure.yaml), removed at the end, and an earlier check's are removed."""
    foresight = Path(sys.executable).parent / "foresight"
    if not foresight.is_file():
        pytest.skip(f"no foresight command at {foresight} (make setup)")
    clone = tmp_path / "clone"  # the script works in the clone it is in: a copy, so that runs/ here stays as it is
    (clone / "tools").mkdir(parents=True)
    shutil.copy(CHECK, clone / "tools" / CHECK.name)
    stale = clone / "runs" / "compose-check" / "security"
    stale.mkdir(parents=True)
    (stale / "ca.key").write_text("an earlier check's")
    record = tmp_path / "at-up.txt"
    bin_dir = tmp_path / "bin"  # a docker whose engine answers and builds; `compose up` notes the certificates, fails
    bin_dir.mkdir()
    (bin_dir / "docker").write_text(
        '#!/bin/sh\ncase "$1" in\n'
        '  compose) case " $* " in *" up "*) { echo "$FORESIGHT_SECURITY_DIR"; ls "$FORESIGHT_SECURITY_DIR"; } '
        f'> "{record}"; exit 1 ;; esac ;;\n'
        "  image) echo 2000000000 ;;\nesac\nexit 0\n")
    (bin_dir / "docker").chmod(0o755)
    env = {"PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "HOME": str(tmp_path), "TMPDIR": str(tmp_path),
           "FORESIGHT": str(foresight), "FORESIGHT_WHEELHOUSE_DIR": str(tmp_path / "none")}
    proc = subprocess.run(["bash", str(clone / "tools" / CHECK.name), "--secure", "--no-demo"], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and "compose check: FAILED: up (see" in proc.stdout, proc.stdout + proc.stderr
    assert "removed runs/compose-check/security: an earlier check's certificates" in proc.stdout
    assert not stale.exists()
    where, *files = record.read_text().split()
    security = Path(where)
    assert {"ca.crt", "ca.key", "router.crt", "router.key", "planner.key"} <= set(files)  # all made, for `up`
    for mounted in ("runs", "models"):  # compose.yaml mounts these two of the clone into every container
        assert not security.is_relative_to(clone / mounted), security
    assert not security.is_relative_to(clone)
    assert not security.exists() and not security.parent.exists(), "the check's certificates were left behind"
