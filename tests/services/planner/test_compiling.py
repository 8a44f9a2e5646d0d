"""A planning process compiles every shape it plans, in every thread (past 8 graphs a function ran eagerly)."""

from __future__ import annotations

import threading

import torch
from torch._dynamo.utils import counters

from services.planner.compiling import compile_every_shape


def _graphs_in_thread(fn, shapes: range) -> int:
    """Unique graphs dynamo made while ``fn`` ran on zeros of each of ``shapes``, in a thread of its own."""
    before = counters["stats"]["unique_graphs"]
    thread = threading.Thread(target=lambda: [fn(torch.zeros(n)) for n in shapes])
    thread.start()
    thread.join(timeout=120)
    assert not thread.is_alive()
    return counters["stats"]["unique_graphs"] - before


def _plus_one(x: torch.Tensor) -> torch.Tensor:
    return x + 1.0


def _times_two(x: torch.Tensor) -> torch.Tensor:
    return x * 2.0


def test_more_shapes_than_dynamos_default_limit_are_all_compiled() -> None:
    """A report worker planned K = 1 and 2 at 40 and 101 waypoints: past 8 graphs its shapes ran eagerly, which
    rounds differently, so two reports of the same code differed where a worker had run other parts before."""
    fn = compile_every_shape(_plus_one, backend="eager", dynamic=False)  # dynamo's graphs, without inductor's time
    assert _graphs_in_thread(fn, range(1, 13)) == 12  # 12 shapes: each its own graph, none run eagerly


def test_the_limit_holds_in_threads_other_than_the_one_that_compiled_first() -> None:
    """Each lock-step run plans in threads of its own; dynamo's config is per thread (torch 2.13), so a limit set
    in the config by the first planner's thread left the later runs' threads at 8 (the log of the next report)."""
    fn = compile_every_shape(_times_two, backend="eager", dynamic=False)
    fn(torch.zeros(1))  # compiled first here, in the test's thread
    assert _graphs_in_thread(fn, range(2, 14)) == 12  # then 12 more shapes in another thread: every one compiled

