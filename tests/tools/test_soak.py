"""``foresight bench soak``'s summary: the reaction latency when the predictor grids only the newest pose; soak and
faults close what they started when stopped by SIGTERM."""

from __future__ import annotations

import signal
from types import SimpleNamespace as NS

import pytest

from tools.soak import _cover_latency


def test_reaction_latency_is_the_first_grid_for_the_pose_or_a_later_one():
    poses = [(0.0, NS(demo_id=1, index=0)), (0.1, NS(demo_id=1, index=1)), (0.2, NS(demo_id=1, index=2)),
             (0.3, NS(demo_id=2, index=0)), (0.4, NS(demo_id=1, index=3))]
    grids = [(0.25, NS(demo_id=1, index=2)),   # covers poses 0, 1, 2 of demo 1 (coalesced)
             (0.35, NS(demo_id=1, index=1)),   # an older index: covers nothing new
             (0.5, NS(demo_id=3, index=9))]    # another demonstration: covers nothing of demo 1 or 2
    lat = _cover_latency(poses, grids)
    assert lat == pytest.approx([0.25, 0.15, 0.05])  # demo 2's pose and index 3 are never covered
    assert _cover_latency(poses, []) == []


SIGTERMED = """
import sys, time
import tools.{bench} as bench

class Processes:  # stands in for the router and the four services: what matters is that close() runs
    def __init__(self, spec):
        self.endpoint = "tcp/127.0.0.1:1"
    def start_router(self):
        pass
    def start_services(self):
        print("started", flush=True)
        time.sleep(60)
    def close(self):
        print("closed", flush=True)
        return {{}}

class Watcher:
    def __init__(self, *args, **kwargs):
        pass
    def __enter__(self):
        return self
    def __exit__(self, *exc):
        return False

bench.ProcessSystem, bench.Watcher, bench.demo_model = Processes, Watcher, lambda models_dir: "model.npz"
from tools.foresight import main
sys.exit(main(["bench", "{bench}"]))
"""


@pytest.mark.parametrize("bench", ["soak", "faults"])
def test_a_bench_stopped_by_sigterm_closes_the_processes_it_started(bench, signalled):
    """SIGTERM ended the bench without its ``finally``: the processes it had started were left to notice by
    themselves, and the router never did (tests/tools/test_router.py)."""
    end = signalled(["-c", SIGTERMED.format(bench=bench)], [(signal.SIGTERM, 0.0)], ready="started", timeout=30)
    assert end.stdout.strip() == "closed" and end.returncode == 130, end.stderr
    assert "foresight: interrupted" in end.stderr


def test_the_soak_says_what_it_waits_for_and_how_far_the_window_is(monkeypatch):
    """It slept through the whole window (60 s by default) without a line; its help showed no default."""
    from tools import soak as soak_module

    clock = [0.0]
    monkeypatch.setattr(soak_module.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(soak_module.time, "sleep", lambda s: clock.__setitem__(0, clock[0] + s))
    system = NS(wait_moving=lambda watcher, timeout: None, rss=dict, procs={})
    pose = NS(demo_id=0, index=0)
    poses = [(-3.0, pose), (-1.0, pose), (4.0, pose), (15.0, pose)]  # the last one comes after the first line
    watcher = NS(poses=poses, occupancy=[], plans=[], states=[],
                 snapshot=lambda xs: [p for p in xs if p[0] <= clock[0]])
    lines: list[str] = []
    soak_module.soak(system, watcher, 25.0, 240.0, progress=lines.append)
    assert lines == ["soak: waiting for the robot to move (at most 240 s)", "soak: the robot moves; measuring 25 s",
                     "soak: 10 / 25 s, 1 poses in the window", "soak: 20 / 25 s, 2 poses in the window"]


def test_the_soak_names_each_process_that_was_not_running_at_the_end(tmp_path, monkeypatch, capsys):
    """It exited 1 with only "rss predictor 160 MB -> 0 MB" to say why."""
    from tools import soak as soak_module

    dead = NS(running=False, returncode=-9, log_path=tmp_path / "predictor.log")
    alive = NS(running=True, returncode=None, log_path=tmp_path / "planner.log")
    system = NS(wait_moving=lambda watcher, timeout: None, rss=dict, procs={"predictor": dead, "planner": alive})
    watcher = NS(poses=[], occupancy=[], plans=[], states=[], snapshot=lambda xs: list(xs))
    monkeypatch.setattr(soak_module.time, "sleep", lambda s: None)
    r = soak_module.soak(system, watcher, 0.01)

    class Processes:
        def __init__(self, spec):
            self.endpoint = "tcp/127.0.0.1:1"

        def start_router(self):
            pass

        def start_services(self):
            pass

        def close(self):
            return {}

    class Watcher:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    monkeypatch.setattr(soak_module, "ProcessSystem", Processes)
    monkeypatch.setattr(soak_module, "Watcher", Watcher)
    monkeypatch.setattr(soak_module, "demo_model", lambda models_dir: tmp_path / "m.npz")
    monkeypatch.setattr(soak_module, "soak", lambda *a, **k: r)
    assert soak_module.main(["--run-dir", str(tmp_path)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"foresight bench soak: predictor was not running at the window's end: it was killed (SIGKILL); its log: "
        f"{tmp_path / 'predictor.log'}"]


def test_the_soak_and_faults_help_show_their_defaults(capsys):
    from tools import faults, soak

    for module in (soak, faults):
        with pytest.raises(SystemExit):
            module.main(["--help"])
        out = capsys.readouterr().out
        assert "(default: " in out and "``" not in out and ":mod:" not in out, module.__name__
