"""The image's entrypoint runs the command as the owner of runs/ (tools/docker_entrypoint.sh)."""

from __future__ import annotations

import os
import shutil
import subprocess
import threading
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ENTRYPOINT = REPO / "tools" / "docker_entrypoint.sh"


def _env(**env: str) -> dict[str, str]:
    """The entrypoint's environment: PATH and ``env``, nothing of the test's own.

    With the whole of ``os.environ``, the tests run as root re-owned, recursively, whatever the caller's
    TORCHINDUCTOR_CACHE_DIR named (a review): the entrypoint hands that directory to the user it steps down to.
    """
    return {"PATH": os.environ["PATH"], **env}


def _as_entrypoint(runs: Path, *command: str, **env: str) -> str:
    out = subprocess.run(["sh", str(ENTRYPOINT), *command], capture_output=True, text=True, timeout=30,
                         env=_env(FORESIGHT_RUNS_DIR=str(runs), **env))
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
                             env=_env(FORESIGHT_RUN_AS=bad))
        assert out.returncode == 2 and out.stderr.strip() == \
            f"foresight-entrypoint: FORESIGHT_RUN_AS={bad} is not UID:GID (numbers)", (bad, out.stderr)
    out = subprocess.run(["sh", str(ENTRYPOINT), "id", "-u"], capture_output=True, text=True, timeout=30,
                         env=_env(FORESIGHT_RUNS_DIR=str(tmp_path / "none")))
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


def _owned_runs(tmp_path: Path, uid: int = 12345) -> Path:
    runs = tmp_path / "runs"
    runs.mkdir()
    os.chown(runs, uid, uid)
    return runs


def _cache(tmp_path: Path) -> Path:
    """A compile cache filled by root: a file in a subdirectory."""
    (tmp_path / "cache" / "kernels").mkdir(parents=True)
    (tmp_path / "cache" / "kernels" / "k.so").write_text("x")
    return tmp_path / "cache"


@needs_root
def test_the_compile_cache_becomes_the_users_and_only_the_one_named(tmp_path: Path, monkeypatch) -> None:
    """The cache the container is given (TORCHINDUCTOR_CACHE_DIR) becomes the user's; the test's own is untouched."""
    runs, cache = _owned_runs(tmp_path), _cache(tmp_path)
    decoy = tmp_path / "decoy"  # the caller's own cache: what the test passes the entrypoint must not reach it
    decoy.mkdir()
    (decoy / "k.so").write_text("x")
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(decoy))
    try:
        assert _as_entrypoint(runs, "id", "-u") == "12345"
        assert (decoy / "k.so").stat().st_uid == decoy.stat().st_uid == 0
        assert _as_entrypoint(runs, "id", "-u", TORCHINDUCTOR_CACHE_DIR=str(cache)) == "12345"
        assert {p.stat().st_uid for p in (cache, cache / "kernels", cache / "kernels" / "k.so")} == {12345}
    finally:
        shutil.rmtree("/tmp/foresight-home-12345", ignore_errors=True)


def _chown_that_says(tmp_path: Path, message: str) -> Path:
    """A bin directory whose ``chown -R`` does the work and then fails with ``message``, as GNU chown does when a
    file goes away under it (``cannot access '...': No such file or directory``) or cannot be changed."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "chown").write_text(f'#!/bin/sh\n{shutil.which("chown")} "$@" || exit\n'
                                   f'[ "$1" = -R ] || exit 0\necho "chown: {message}" >&2\nexit 1\n')
    (bin_dir / "chown").chmod(0o755)
    return bin_dir


@needs_root
@pytest.mark.parametrize("message, warning", [
    ("cannot access '/cache/kernels/tmp_x.so': No such file or directory", ""),
    ("changing ownership of '/cache/k.so': Read-only file system",
     "warning: {cache} is not wholly 12345:12345's, kernels may be compiled again: chown: changing ownership of "
     "'/cache/k.so': Read-only file system"),
])
def test_a_failing_chown_of_the_cache_never_stops_the_container(tmp_path: Path, message: str, warning: str) -> None:
    """The planner compiling into the shared cache removes files while another container's entrypoint walks it: a
    file gone mid-walk ended that container under `set -e` (3 starts in 20 in a review). Now it is no error, and
    any other failure of the chown is one warning line; the command runs, as the owner of runs/."""
    runs, cache = _owned_runs(tmp_path), _cache(tmp_path)
    bin_dir = _chown_that_says(tmp_path, message)
    try:
        out = subprocess.run(["sh", str(ENTRYPOINT), "id", "-u"], capture_output=True, text=True, timeout=30,
                             env=_env(PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}", FORESIGHT_RUNS_DIR=str(runs),
                                      TORCHINDUCTOR_CACHE_DIR=str(cache)))
    finally:
        shutil.rmtree("/tmp/foresight-home-12345", ignore_errors=True)
    assert out.returncode == 0 and out.stdout.strip() == "12345", out.stderr
    expected = f"foresight-entrypoint: {warning.format(cache=cache)}" if warning else ""
    assert out.stderr.strip() == expected


@needs_root
def test_files_coming_and_going_in_the_cache_while_it_is_walked(tmp_path: Path) -> None:
    """The race itself: another process adds and removes files in the cache while the entrypoint starts 20 times."""
    runs, cache = _owned_runs(tmp_path), _cache(tmp_path)
    for i in range(300):
        (cache / f"d{i}").mkdir()
        for j in range(5):
            (cache / f"d{i}" / f"f{j}").write_text("x")
    done = threading.Event()

    def churn() -> None:
        while not done.is_set():
            for i in range(300):
                shutil.rmtree(cache / f"d{i}", ignore_errors=True)
                (cache / f"d{i}").mkdir(exist_ok=True)
                (cache / f"d{i}" / "f0").write_text("y")

    worker = threading.Thread(target=churn, daemon=True)
    worker.start()
    try:
        runs_ = [subprocess.run(["sh", str(ENTRYPOINT), "true"], capture_output=True, text=True, timeout=30,
                                env=_env(FORESIGHT_RUNS_DIR=str(runs), TORCHINDUCTOR_CACHE_DIR=str(cache)))
                 for _ in range(20)]
    finally:
        done.set()
        worker.join(10)
        shutil.rmtree("/tmp/foresight-home-12345", ignore_errors=True)
    failed = [r.stderr.strip() for r in runs_ if r.returncode != 0 or r.stderr]
    assert not failed, f"{len(failed)} of 20 starts: {failed[0]}"
