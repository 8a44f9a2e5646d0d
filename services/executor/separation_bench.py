"""``foresight bench separation``: the separation guard against noisy poses of a person in the way, and its cost.

The PR2 follows a straight joint-space path from its start towards a goal; the person stands (a synthetic
demonstration's first pose, moved) so that one of the body's capsules lies on the robot's hand at the goal: the
path's clearance falls from over 0.15 m to under 0. Each run steps the executor's core at 50 states a second for
``--seconds`` with a new pose every state, its features noisy (Gaussian per pose, or drifting: each error 0.9 of the
last), and prints where the robot ends, measured against the true body: with the guard's window (the nearest body of
the last ``window_s``) and, as the baseline in the same process, with the newest pose alone (``window_s`` 0). Then the
guard's time per state against the bodies of a 30 Hz sensor's window and, as the baseline, calls interleaved with
them, against the newest body alone (``window_s`` 0), with the ratio of the two; and per pose (one thread). Both at
``--stop-m`` (0: the guard is off, and a call costs nothing).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from shared.arguments import ArgumentParser
from shared.clearance import body_clearance, sphere_centres
from shared.human import HumanModel, StreamPlacement
from shared.native_threads import limit_blas_threads
from shared.protocol import HumanPose, Plan, ProtocolError
from shared.runtime import cli_errors
from shared.scene import load_scene
from shared.synthetic import generate_library

from .config import ExecutorConfig, SeparationConfig
from .core import ArmLimits, ExecutorCore
from .models import load_models, start_configuration
from .separation import SeparationGuard

__all__ = ["main", "in_the_way"]

H = 0.02  # s, one state
NOISE = (("none", 0.0, 0.0, False), ("1 cm, 0.03 rad", 0.01, 0.03, False), ("2 cm, 0.05 rad", 0.02, 0.05, False),
         ("0.05 rad drifting", 0.0, 0.05, True))
"""(name, pelvis noise m, joint-angle noise rad, drifting) of each row."""


def in_the_way(robot, scene, limits: ArmLimits) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The bench's setting (the guard's tests share it): ``(q0, goal, away, near)``, each ``(D,)`` or ``(12,)``.

    The robot's start ``q0`` and a ``goal`` 0.3-0.5 rad away on the first four arm joints (towards the side with
    room); recorder-frame features of the person where the scene places them (a synthetic demonstration's first
    pose), ``away``, and moved so that one of the body's capsules lies on the robot's hand (the sphere the path moves
    most) at the goal, ``near``: the straight path's clearance falls from over 0.15 m to under 0.
    """
    q0 = start_configuration(limits, ExecutorConfig(), robot, scene)
    goal = q0.copy()
    for i, d in enumerate((0.5, 0.3, -0.4, -0.5), start=1):
        goal[i] = q0[i] + d if limits.lower[i] + 0.05 <= q0[i] + d <= limits.upper[i] - 0.05 else q0[i] - d
    goal = np.clip(goal, limits.lower + 0.05, limits.upper - 0.05)
    centres = sphere_centres(robot, np.stack([q0, goal]))
    hand = int(np.argmax(np.linalg.norm(centres[1] - centres[0], axis=1)))
    human, away = HumanModel(), generate_library(seed=0).demos[0].features[0].astype(np.float64)
    placement = StreamPlacement(scene)
    ends, _ = human.capsules(placement.place(0, 0, away))
    turn = away[3] - scene.human.pelvis_yaw  # the scene's frame back to the recorder's
    rotate = np.array([[math.cos(turn), -math.sin(turn), 0.0], [math.sin(turn), math.cos(turn), 0.0], [0, 0, 1.0]])
    path = np.linspace(q0, goal, 30)
    for capsule in ends.mean(axis=1):
        near = away.copy()
        near[:3] += rotate @ (centres[1][hand] - capsule)
        try:
            HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=0, index=1, features=near).check()
        except ProtocolError:
            continue  # a pelvis the wire would refuse
        clear = body_clearance(robot, path, np.repeat(placement.place(0, 1, near)[None], 30, 0), human)
        if clear[0] > 0.15 and clear[-1] < 0:
            return q0, goal, away, near
    raise RuntimeError("bench separation: no capsule of the body lies across the robot's path")


def main(argv: list[str] | None = None, prog: str = "foresight bench separation") -> int:
    """Run the benchmark; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="runs per noise level")
    parser.add_argument("--seconds", type=float, default=8.0, help="length of each run (s)")
    parser.add_argument("--stop-m", type=float, default=SeparationConfig().stop_m, help="the guard's stop_m")
    args = parser.parse_args(argv)
    if args.seeds < 1 or not args.seconds > 0:
        parser.error("--seeds must be >= 1 and --seconds > 0")
    if not (args.stop_m >= 0 and math.isfinite(args.stop_m)):
        parser.error(f"--stop-m must be a finite number >= 0 (0: the guard off), got {args.stop_m:g}")
    with cli_errors(prog):
        return _bench(prog, args.seeds, args.seconds, args.stop_m)


def _bench(prog: str, seeds: int, seconds: float, stop_m: float) -> int:
    """The benchmark of :func:`main`'s checked options."""
    limit_blas_threads(1)
    import torch

    torch.set_num_threads(1)
    scene = load_scene(None)
    robot, _, _ = load_models(scene, "cpu")
    limits = ArmLimits.from_robot(robot)
    q0, goal, away, near = in_the_way(robot, scene, limits)
    placement = StreamPlacement(scene)
    placement.place(0, 0, away)
    truth, human = placement.place(0, 1, near), HumanModel()
    print(f"{prog}: the PR2 on a straight path into a body ({seconds:g} s at 50 states a second, a pose each), "
          f"stop_m {stop_m:g} m; true clearance where the robot ends (m), seeds 0-{seeds - 1}")
    print(f"{'noise per pose':<20}{'window 0.5 s':>24}{'newest pose only':>24}")
    for name, pelvis, angles, drifting in NOISE:
        cells = []
        for window in (0.5, 0.0):
            ends = [_run(robot, limits, scene, q0, goal, away, near, SeparationConfig(stop_m, window), pelvis,
                         angles, drifting, seed, seconds) for seed in range(seeds)]
            cells.append(", ".join(f"{body_clearance(robot, q[None], truth[None], human)[0]:+.3f}" for q in ends))
        print(f"{name:<20}{cells[0]:>24}{cells[1]:>24}")
    call_ms, newest_ms, pose_ms = _timing(robot, scene, q0, stop_m)
    print(f"time per state (15 bodies, a 30 Hz sensor's half second): median {call_ms:.2f} ms, {call_ms * 5:.1f} % "
          f"of a core at 50 states a second; per pose (its capsules): {pose_ms:.2f} ms")
    ratio = f"{call_ms / newest_ms:.1f}x" if newest_ms > 0 else "-"
    print(f"baseline, the newest body alone (window 0): median {newest_ms:.2f} ms a state; the window costs {ratio} "
          "as much")
    return 0


def _run(robot, limits: ArmLimits, scene, q0: np.ndarray, goal: np.ndarray, away: np.ndarray, near: np.ndarray,
         config: SeparationConfig, pelvis: float, angles: float, drifting: bool, seed: int,
         seconds: float) -> np.ndarray:
    """``(D,)`` where the robot ends after ``seconds`` of noisy poses of the person at ``near``."""
    rng = np.random.default_rng(seed)
    guard = SeparationGuard(config, robot, scene)
    guard.note_pose(0, 0, away, 0.0)
    core = ExecutorCore(limits, q0, ExecutorConfig(mode="realtime", require_occupancy=False, stale_limit_s=1e6),
                        guard=guard)
    core.adopt(_straight_plan(q0, goal, limits))
    error = np.zeros(12)
    for i in range(round(seconds / H)):
        fresh = np.r_[rng.normal(0.0, pelvis, 3), 0.0, rng.normal(0.0, angles, 8)]
        error = 0.9 * error + math.sqrt(1 - 0.81) * fresh if drifting else fresh
        guard.note_pose(0, i + 1, near + error, (i + 1) * H)
        core.step(H)
    return core.q.copy()


def _straight_plan(q0: np.ndarray, goal: np.ndarray, limits: ArmLimits) -> Plan:
    traj = np.linspace(q0, goal, 15)[None].astype(np.float32)
    one = np.ones(1)
    return Plan(stamp=time.time(), tick=-1, step=0, goal_names=["goal"], joint_names=list(limits.joint_names), dt=0.1,
                chosen=0, planning_ms=1.0, occupancy_tick=-1, occupancy_index=0, trajectories=traj,
                cost_smoothness=one, cost_obstacle=one * 0, cost_human=one, cost_total=2 * one,
                valid=np.ones(1, bool))


def _timing(robot, scene, q0: np.ndarray, stop_m: float) -> tuple[float, float, float]:
    """Median ms of a guard call against 15 bodies, of one against the newest body alone, and of a pose noted."""
    guard = SeparationGuard(SeparationConfig(stop_m), robot, scene)
    newest = SeparationGuard(SeparationConfig(stop_m, window_s=0.0), robot, scene)  # the baseline
    features = generate_library(seed=0).demos[0].features
    for i in range(15):
        guard.note_pose(0, i, features[i], i / 30)
        newest.note_pose(0, i, features[i], i / 30)
    q1 = q0 + 0.005
    calls, alone, poses = [], [], []
    for i in range(200):
        for g, times in ((guard, calls), (newest, alone))[:: 1 if i % 2 else -1]:  # neither always goes first
            t = time.perf_counter()
            g(q0, q1)
            times.append(time.perf_counter() - t)
    for i in range(200):
        t = time.perf_counter()
        guard.note_pose(0, 15 + i, features[i % len(features)], (15 + i) / 30)
        poses.append(time.perf_counter() - t)
    return float(np.median(calls) * 1e3), float(np.median(alone) * 1e3), float(np.median(poses) * 1e3)


if __name__ == "__main__":
    sys.exit(main())
