"""The image's entrypoint runs the command as the owner of runs/ (tools/docker_entrypoint.sh)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ENTRYPOINT = REPO / "tools" / "docker_entrypoint.sh"


def _as_entrypoint(runs: Path, *command: str, **env: str) -> str:
    out = subprocess.run(["sh", str(ENTRYPOINT), *command], capture_output=True, text=True, timeout=30,
                         env={**os.environ, "FORESIGHT_RUNS_DIR": str(runs), **env})
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


needs_root = pytest.mark.skipif(os.getuid() != 0 or shutil.which("setpriv") is None,
                                reason="stepping down to another user needs root and setpriv (the image has both)")


@needs_root
def test_a_root_container_runs_its_command_as_the_owner_of_runs(tmp_path: Path) -> None:
    """Compose ran every container as 1000:1000: any other user's `docker compose up` failed in prepare with
    'Permission denied', and a secure cell's keys (0600, their maker's) could not be read."""
    runs = tmp_path / "runs"
    runs.mkdir()
    os.chown(runs, 12345, 12346)
    try:
        assert _as_entrypoint(runs, "sh", "-c", 'echo "$(id -u):$(id -g) $HOME"') == \
            "12345:12346 /tmp/foresight-home-12345"
        assert _as_entrypoint(runs, "id", "-u", FORESIGHT_RUN_AS="4242:4243") == "4242"  # named explicitly
    finally:
        for uid in (12345, 4242):
            shutil.rmtree(f"/tmp/foresight-home-{uid}", ignore_errors=True)


@needs_root
def test_a_runs_directory_owned_by_root_runs_the_command_as_root(tmp_path: Path) -> None:
    assert _as_entrypoint(tmp_path, "id", "-u") == "0"


def test_the_arguments_reach_the_command_unchanged(tmp_path: Path) -> None:
    """Started as any user, the command gets its arguments as given (spaces and all)."""
    assert _as_entrypoint(tmp_path, "printf", "%s|", "a b", "--flag=x y") == "a b|--flag=x y|"
