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


@needs_root
def test_a_bad_run_as_or_a_missing_runs_directory_is_one_line(tmp_path: Path) -> None:
    for bad in ("4242", "4242:", ":1", "a:b", "1:2:3"):
        out = subprocess.run(["sh", str(ENTRYPOINT), "id", "-u"], capture_output=True, text=True, timeout=30,
                             env={**os.environ, "FORESIGHT_RUN_AS": bad})
        assert out.returncode == 2 and out.stderr.strip() == \
            f"foresight-entrypoint: FORESIGHT_RUN_AS={bad} is not UID:GID (numbers)", (bad, out.stderr)
    out = subprocess.run(["sh", str(ENTRYPOINT), "id", "-u"], capture_output=True, text=True, timeout=30,
                         env={**os.environ, "FORESIGHT_RUNS_DIR": str(tmp_path / "none")})
    assert out.returncode == 2 and "is not a directory: mount the clone's runs/ there" in out.stderr


@needs_root
def test_without_setpriv_the_command_runs_as_root_and_says_why(tmp_path: Path) -> None:
    """A base image without setpriv failed every container with 'setpriv: not found' (a review)."""
    runs = tmp_path / "runs"
    runs.mkdir()
    os.chown(runs, 12345, 12345)
    bin_dir = tmp_path / "bin"  # a PATH with the shell's tools but no setpriv
    bin_dir.mkdir()
    for tool in ("id", "stat", "mkdir", "chown"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    out = subprocess.run([shutil.which("sh"), str(ENTRYPOINT), "id", "-u"], capture_output=True, text=True,
                         timeout=30, env={"PATH": str(bin_dir), "FORESIGHT_RUNS_DIR": str(runs)})
    assert out.returncode == 0 and out.stdout.strip() == "0" and "setpriv (util-linux) is missing" in out.stderr
