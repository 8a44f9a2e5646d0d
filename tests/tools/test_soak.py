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
