"""``foresight bench body``: the planner's body term (``services.planner.body``), what it changes and what it costs.

The person at rest at the end of a reach (the last pose of the synthetic library's first demonstration of each cup's
class, placed in the scene from its first pose, as the predictor and the guard place it); the robot at its start,
replanning ``--steps`` times for every goal as in real time (each step warm-started from the last), with no predicted
occupancy, so the body term alone keeps the plan off the person. Each setting runs with the term (real time's cost,
``body_clearance`` 0.10 m) and without it (0: the lock-step cost), in the same process: the goal chosen at the last
step, the least clearance between the robot and the body along its path (under the executor's ``stop_m`` the guard
holds the robot there), and the median time of a step.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys

import numpy as np

from shared.arguments import ArgumentParser
from shared.clearance import body_clearance
from shared.human import HumanModel, StreamPlacement
from shared.native_threads import limit_blas_threads
from shared.scene import load_scene
from shared.synthetic import generate_library

__all__ = ["main"]


def _resting(scene, library, class_name: str) -> np.ndarray:
    """``(12,)`` the scene-frame posture at the end of the library's first reach of ``class_name``."""
    demo = next(d for d in library.demos if d.class_name == class_name)
    placement = StreamPlacement(scene)
    placement.place(0, 0, demo.features[0].astype(np.float64))
    return placement.place(0, len(demo.features) - 1, demo.features[-1].astype(np.float64))


def main(argv: list[str] | None = None, prog: str = "foresight bench body") -> int:
    """Run the benchmark; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=6, help="replanning steps per setting (the first is not timed)")
    parser.add_argument("--compile", action=argparse.BooleanOptionalAction, default=True,
                        help="torch.compile the cost and STOMP's steps (default on, as PlannerConfig)")
    args = parser.parse_args(argv)
    if args.steps < 2:
        parser.error("--steps must be >= 2 (the first step is not timed)")
    limit_blas_threads(1)
    import torch

    from .config import CostConfig, PlannerConfig
    from .core import Planner

    torch.set_num_threads(1)
    scene = load_scene(None)
    human = HumanModel()
    config = PlannerConfig(compile=args.compile)
    on = Planner(scene, config)
    off = Planner(scene, dataclasses.replace(config, cost=dataclasses.replace(config.cost, body_clearance=0.0)),
                  robot=on.robot)
    q0 = on.robot.q_start.double().numpy()
    empty = np.zeros(scene.grid.dims, dtype=np.float32)
    eps = CostConfig().body_clearance
    print(f"{prog}: the person at rest after a reach, the robot replanning from its start for "
          f"{', '.join(on.goals.names)}, {args.steps} steps, no predicted occupancy; body_clearance {eps:g} m against "
          f"0 (same process)")
    print(f"{'person at rest after':<22}{'term':<6}{'chosen':<12}{'least clearance (m)':>21}{'step (ms, median)':>19}")
    times: dict[str, list[float]] = {"on": [], "off": []}
    library = generate_library(seed=0)
    for class_name in [c for c in library.class_names if c in on.goals.names]:  # a reach to each goal's cup
        posture = _resting(scene, library, class_name)
        ends, radii = human.capsules(posture)
        for name, planner in (("on", on), ("off", off)):
            planner.reset()
            planner.cost.set_body(ends, radii)  # the "off" cost (body_clearance 0) holds it and ignores it
            results = [planner.step(q0, empty) for _ in range(args.steps)]
            last = results[-1]
            path = last.trajectories[last.chosen].astype(np.float64)
            clear = float(body_clearance(planner.robot, path, np.repeat(posture[None], len(path), 0), human).min())
            ms = statistics.median(r.planning_ms for r in results[1:])
            times[name].append(ms)
            print(f"{class_name:<22}{name:<6}{last.goal_names[last.chosen]:<12}{clear:>+21.3f}{ms:>19.1f}")
    ratio = statistics.median(times["on"]) / statistics.median(times["off"])
    print(f"step time with the term / without: {ratio:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
