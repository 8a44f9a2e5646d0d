"""The README's "Running one service" lines, run as written, one process per line, in a fresh directory.

Deviations from pasting the lines into a shell, each because of where the test runs:

* ``.venv/bin/foresight`` / ``.venv/bin/python`` are this interpreter (``python -m tools`` /
  ``python``), with the repository on ``PYTHONPATH``: the test may run from a checkout without
  ``.venv``, in a fresh working directory so that it neither reads nor writes the repo's ``models/``;
* the router listens on a free loopback port instead of 7447 (which another run may hold), given to
  each process through the documented environment variables (``FORESIGHT_ZENOH_LISTEN`` for the
  router, ``FORESIGHT_ZENOH_CONNECT`` for the services): the lines themselves are unchanged;
* ``train`` gets ``--components 3``, the quick option the README offers next to the lines.

``CMD &`` starts a background process, ``NAME=$!`` after it names it, ``kill $NAME`` sends it
SIGTERM; any other line runs to completion. Every process is stopped with a bounded timeout.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from services.processes import free_port
from shared.config import ZenohConfig
from shared.protocol import Keys, Plan
from shared.recording.reader import read_log
from shared.transport import open_session, subscribe

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
QUICK_TRAIN = "--components 3"


def section_lines() -> list[str]:
    """The lines of the first code block of the README's "Running one service" section."""
    text = README.read_text()
    section = text[text.index("## Running one service"):]
    section = section[:section.index("\n## ", 1)]
    block = re.search(r"^```\n(.*?)^```", section, re.S | re.M)
    assert block is not None, "no code block in 'Running one service'"
    return [ln for ln in block[1].splitlines() if ln.strip()]


@dataclass
class Step:
    """One README line: the command, whether it runs in the background, the name ``$!`` gets, or a kill."""

    argv: list[str]
    background: bool = False
    name: str | None = None
    kill: str | None = None
    line: str = ""


def parse(line: str) -> Step:
    tokens = shlex.split(line, comments=True)
    if tokens[0] == "kill":
        assert len(tokens) == 2 and tokens[1].startswith("$"), line
        return Step([], kill=tokens[1][1:], line=line)
    step = Step(tokens, line=line)
    if "&" in tokens:
        i = tokens.index("&")
        step.argv, rest = tokens[:i], tokens[i + 1:]
        step.background = True
        if rest:
            m = re.fullmatch(r"(\w+)=\$!", rest[0])
            assert m is not None and len(rest) == 1, line
            step.name = m[1]
    return step


def command(argv: list[str]) -> list[str]:
    tool, args = argv[0], argv[1:]
    if tool == ".venv/bin/foresight":
        return [sys.executable, "-m", "tools", *args]
    if tool == ".venv/bin/python":
        return [sys.executable, *args]
    raise AssertionError(f"README line does not start with .venv/bin/foresight or .venv/bin/python: {argv}")


def test_the_lines_parse_and_name_real_commands() -> None:
    steps = [parse(ln) for ln in section_lines()]
    assert any(s.background for s in steps) and any(s.kill for s in steps)
    for s in steps:
        if s.argv:
            command(s.argv)
    names = {s.name for s in steps if s.name}
    assert {s.kill for s in steps if s.kill} <= names
    assert QUICK_TRAIN in README.read_text()


@dataclass
class Run:
    work: Path
    port: int
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    logs: dict[str, Path] = field(default_factory=dict)

    def env(self, argv: list[str]) -> dict[str, str]:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
               "PYTHONUNBUFFERED": "1", "FORESIGHT_ZENOH_MULTICAST_SCOUTING": "false"}
        endpoint = f"tcp/127.0.0.1:{self.port}"
        if argv[1:2] == ["router"]:
            env["FORESIGHT_ZENOH_LISTEN"] = endpoint
        else:
            env["FORESIGHT_ZENOH_CONNECT"] = endpoint
        return env

    def log(self, key: str) -> str:
        path = self.logs.get(key)
        return path.read_text(errors="replace")[-3000:] if path and path.exists() else ""


def stop(proc: subprocess.Popen[bytes], timeout: float = 20.0) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
    return proc.returncode


@pytest.mark.slow
def test_running_one_service_lines_yield_a_plan(tmp_path) -> None:
    steps = [parse(ln) for ln in section_lines()]
    run = Run(tmp_path, free_port())
    plans: list[Plan] = []
    got_plan = threading.Event()

    def on_plan(msg: Plan) -> None:
        plans.append(msg)
        got_plan.set()

    watch = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[f"tcp/127.0.0.1:{run.port}"])
    executor_out = ""
    try:
        with open_session(watch) as session:
            sub = subscribe(session, Keys().plan, Plan, on_plan)
            for n, step in enumerate(steps):
                key = step.name or f"{n}"
                if step.kill:
                    assert stop(run.procs[step.kill]) == 0, run.log(step.kill)
                    continue
                argv = list(step.argv)
                if argv[:2] == [".venv/bin/foresight", "train"]:
                    argv += shlex.split(QUICK_TRAIN)
                run.logs[key] = tmp_path / f"line{n}.log"
                with run.logs[key].open("wb") as out:
                    proc = subprocess.Popen(command(argv), cwd=tmp_path, env=run.env(argv), stdout=out,
                                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
                run.procs[key] = proc
                if step.background:
                    continue
                try:
                    code = proc.wait(timeout=300)
                except subprocess.TimeoutExpired:
                    pytest.fail(f"{step.line!r} did not finish within 300 s:\n{run.log(key)}")
                assert code == 0, f"{step.line!r} exited with {code}:\n{run.log(key)}"
                if argv[:2] == [".venv/bin/foresight", "executor"]:
                    executor_out = run.log(key)
            sub.undeclare()
        # the services started with --stop-with executor end by themselves
        for key, proc in run.procs.items():
            try:
                code = proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pytest.fail(f"line {key} still runs 30 s after the executor ended:\n{run.log(key)}")
            assert code == 0, f"line {key} exited with {code}:\n{run.log(key)}"
    finally:
        for proc in run.procs.values():
            stop(proc, timeout=10)
    assert got_plan.is_set() and plans, "no plan seen on the bus"
    assert "mcap: runs/mine.mcap" in executor_out
    lf = read_log(tmp_path / "runs" / "mine.mcap")
    counts = {c.schema_name: c.count for c in lf.channels.values()}
    assert lf.complete and counts.get("foresight.Plan", 0) > 0 and counts.get("foresight.HumanPose", 0) > 0


def test_the_readme_test_count_is_what_make_test_collects(whole_suite_count: int | None) -> None:
    """The README's number of tests is produced by the suite, not typed: `make test` checks it."""
    collected = whole_suite_count
    if collected is None:
        pytest.skip("only a run of the whole suite (make test) knows its count")
    match = re.search(r"runs the test suite \((\d+) tests", README.read_text())
    assert match, "the README says how many tests `make test` runs"
    assert int(match.group(1)) == collected, (f"README says {match.group(1)} tests, `make test` collects {collected}: "
                                              "update the README")
