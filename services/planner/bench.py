"""``foresight bench planner``: time one replanning step (STOMP, all goals batched) against raw FK.

For K = 1, 2, 4, 8, 16 goals (the scene's IK goals, then joint-space perturbations of them) at the
configured rollouts R and waypoints T, it times :meth:`Planner.step` (``iterations`` STOMP
iterations, reconnectPrevious, cost terms) on a synthetic occupancy blob, next to the time of the
robot's batched forward kinematics (``PR2.fk_links``, the kernel the cost uses) for the same number
of configurations (K x R x T per iteration, times the iterations), and prints their ratio; then the
time of the step's cost calls alone (``cost_ms``: what the step cannot spend less than while the cost
is evaluated the same way) and its share of the step.
``--json`` prints one JSON object with (at least) the keys ``K``, ``step_ms`` and ``fk_ms`` (lists).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np
import torch

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.runtime import cli_errors, help_text
from shared.scene import Scene, load_scene

from .core import GoalSet, Planner, PlannerConfig
from .fk_bench import fk_time_ms, synchronize
from .stomp import StompConfig, rollouts

__all__ = ["main", "bench_goals", "blob_occupancy", "run_bench", "convergence"]


def blob_occupancy(scene: Scene, center: tuple[float, float, float] | None = None, sigma: float = 0.12) -> np.ndarray:
    """A synthetic predicted occupancy: a gaussian blob (peak 1) on the scene grid.

    Args:
        scene: Its ``grid`` gives the geometry.
        center: ``(3,)`` world position of the blob (default: between the two first cups, 0.2 m above
            the table).
        sigma: Standard deviation (m).

    Returns:
        ``(nx, ny, nz)`` float32 probabilities.
    """
    if center is None:
        cups = [c.center for c in scene.cups[:2]] or [scene.grid.min + (scene.grid.max - scene.grid.min) / 2]
        center = tuple(np.mean(cups, axis=0) + np.array([0.0, 0.0, 0.2]))
    c = scene.grid.centers()
    return np.exp(-((c - np.asarray(center)) ** 2).sum(-1) / (2 * sigma**2)).astype(np.float32)


def bench_goals(base: GoalSet, robot: Any, k: int, seed: int = 0, spread: float = 0.15) -> GoalSet:
    """``k`` goals: the valid goals of ``base``, then seeded joint-space perturbations of them.

    Args:
        base: Goals with at least one valid entry.
        robot: Gives the joint limits.
        k: Number of goals wanted.
        seed: Perturbation seed.
        spread: Standard deviation of the perturbation (rad; the torso joint gets 1/100 of it).

    Returns:
        ``k`` valid joint-space goals (within the limits).
    """
    idx = torch.nonzero(base.valid).flatten().tolist()
    gen = torch.Generator().manual_seed(seed)
    names, qs = [], []
    for i in range(k):
        j = idx[i % len(idx)]
        q = base.q[j].double().cpu()
        if i >= len(idx):
            scale = torch.full_like(q, spread)
            scale[0] = spread / 100
            q = q + scale * torch.randn(q.shape, generator=gen, dtype=torch.float64)
        names.append(base.names[j] if i < len(idx) else f"{base.names[j]}~{i}")
        qs.append(q)
    lo, hi = robot.lower.double().cpu(), robot.upper.double().cpu()
    q = torch.maximum(torch.minimum(torch.stack(qs), hi), lo)
    return GoalSet.joint_space(names, q.numpy(), robot)


CHECKPOINTS = (0, 5, 10, 20, 30, 40, 50)
"""Iterations at which ``foresight bench planner`` reports the cost reached."""


def convergence(histories: list[np.ndarray], checkpoints: tuple[int, ...] = CHECKPOINTS) -> list[float]:
    """Cost reached against iterations: the best cost so far, summed over the goals, over the final one.

    Args:
        histories: Per step, ``(I + 1, K)`` ``PlanResult.cost_history``.
        checkpoints: Iteration counts (those beyond I are dropped).

    Returns:
        Per checkpoint, the median over the steps of sum_k min_{i' <= i} cost_k(i') / sum_k min_i' cost_k(i').
    """
    ratios = []
    for h in histories:
        best = np.minimum.accumulate(np.asarray(h, dtype=np.float64), axis=0).sum(-1)  # (I + 1,)
        final = best[-1]  # 0 when every reached goal holds outside the occupancy (a held goal pays its dwell)
        ratios.append([best[i] / final if final > 0 else (1.0 if best[i] == 0 else math.inf)
                       for i in checkpoints if i < len(best)])
    n = min(len(r) for r in ratios)
    return [round(float(np.median([r[j] for r in ratios])), 3) for j in range(n)]


def _time_fk(robot: Any, n: int, iterations: int, repeats: int, seed: int) -> tuple[float, float]:
    """Median wall and process-CPU ms of ``iterations`` calls of ``robot.fk_links`` on ``n`` configurations."""
    gen = torch.Generator(device=robot.lower.device).manual_seed(seed)
    q = robot.lower + (robot.upper - robot.lower) * torch.rand(n, robot.lower.shape[0], generator=gen,
                                                               device=robot.lower.device, dtype=robot.lower.dtype)
    robot.fk_links(q)
    synchronize(q.device)
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(iterations):
            robot.fk_links(q)
        synchronize(q.device)
        times.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return statistics.median(times), statistics.median(cpu)


def _time_cost(planner: Planner, res: Any, repeats: int) -> float:
    """Median ms of one step's STOMP cost calls alone: ``iterations`` calls of the cost on ``(K, R + 1, T, D)``.

    Each call costs what STOMP's iteration would: the last plan's trajectories and their noisy rollouts, drawn by
    the planner's own STOMP (its correlated noise, its seeds, clamped to the limits, start and goal fixed). A lower
    bound of the step's cost time: the step also costs the final trajectories, reconnectPrevious's candidates and
    the result's terms.
    """
    st = planner.stomp
    trajs = torch.as_tensor(res.trajectories[planner.valid_index], device=planner.device, dtype=planner.dtype)
    k = trajs.shape[0]
    noise = st.sample_noise(k, [planner.config.seed + i for i in range(k)])  # (I, K, R, N, D)
    start, goal, theta = trajs[:, :1].contiguous(), trajs[:, -1:].contiguous(), trajs[:, 1:-1].contiguous()
    qs = [rollouts(theta, noise[i], start, goal, st.lower, st.upper)[0] for i in range(noise.shape[0])]
    planner.waypoint_cost(qs[0])
    synchronize(planner.device)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for q in qs:
            planner.waypoint_cost(q)
        synchronize(planner.device)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def k_goal_planner(scene: Scene, config: PlannerConfig, k: int, base: Planner | None = None) -> Planner:
    """A planner for ``k`` bench goals sharing ``base``'s robot, cost and IK goals (built if not given)."""
    base = base or Planner(scene, config)
    return Planner(scene, config, robot=base.robot, cost=base.cost,
                   goals=bench_goals(base.goals, base.robot, k, seed=config.seed))


def start_configuration(robot: Any) -> np.ndarray:
    """``(D,)`` the robot's start configuration (mid-range if it has none)."""
    q0 = robot.q_start if getattr(robot, "q_start", None) is not None else (robot.lower + robot.upper) / 2
    return q0.double().cpu().numpy()


def run_bench(ks: list[int], config: PlannerConfig, steps: int = 5, scene: Scene | None = None,
              progress: bool = True) -> dict[str, Any]:
    """Time replanning steps and FK for each K; returns the report dict (see module docstring)."""
    from shared.progress import progress as progress_bar

    scene = scene or load_scene()
    base = Planner(scene, dataclasses.replace(config, compile=False))  # the robot, the cost and the IK goals, once
    occ = blob_occupancy(scene)
    q0 = start_configuration(base.robot)
    out: dict[str, Any] = {"K": [], "step_ms": [], "step_ms_min": [], "step_cpu_ms": [], "fk_ms": [],
                           "fk_cpu_ms": [], "pk_fk_ms": [], "ratio": [], "cost_ms": [], "construct_s": [],
                           "final_cost": [],
                           "compiled": False,
                           "checkpoints": [], "cost_cold": [], "cost_warm": [],
                           "rollouts": config.stomp.rollouts, "waypoints": config.stomp.waypoints,
                           "iterations": config.stomp.iterations, "threads": torch.get_num_threads(),
                           "device": config.device, "dtype": config.dtype, "steps": steps,
                           "load_avg_1min": os.getloadavg()[0]}
    for k in progress_bar(ks, desc="bench planner", unit="K", enabled=progress):
        t0 = time.perf_counter()
        planner = k_goal_planner(scene, config, k, base)
        out["construct_s"].append(round(time.perf_counter() - t0, 2))
        out["compiled"] = bool(planner.fused is not None and planner.fused.compiled)
        res = planner.step(q0, occ)  # warm-up (first step: straight lines)
        cold = res.cost_history
        times, cpu, warm = [], [], []
        for _ in range(steps):
            c0 = time.process_time()
            res = planner.step(res.start, occ)  # the robot is where the last plan starts
            cpu.append((time.process_time() - c0) * 1e3)
            times.append(res.planning_ms)
            warm.append(res.cost_history)
        out["cost_ms"].append(round(_time_cost(planner, res, steps), 2))
        out["cost_cold"].append(convergence([cold]))
        out["cost_warm"].append(convergence(warm))
        out["final_cost"].append(round(float(np.median([np.asarray(h).min(0).sum() for h in warm])), 4))
        st = config.stomp
        fk, fk_cpu = _time_fk(base.robot, k * st.rollouts * st.waypoints, st.iterations, 3, config.seed)
        step_ms = statistics.median(times)
        out["K"].append(k)
        out["step_ms"].append(round(step_ms, 2))
        out["step_ms_min"].append(round(min(times), 2))
        out["step_cpu_ms"].append(round(statistics.median(cpu), 2))
        out["fk_ms"].append(round(fk, 2))
        out["fk_cpu_ms"].append(round(fk_cpu, 2))
        pk = fk_time_ms(k * config.stomp.rollouts * config.stomp.waypoints, "pk", robot=base.robot, repeats=3,
                        seed=config.seed)
        out["pk_fk_ms"].append(round(pk * config.stomp.iterations, 2))
        out["ratio"].append(round(step_ms / fk, 2))
    if 1 in out["K"]:
        one = out["step_ms"][out["K"].index(1)]
        out["time_vs_k1"] = [round(t / one, 2) for t in out["step_ms"]]
    # the iterations run (cost_history has I + 1 rows): a checkpoint past them has no cost in any list
    out["checkpoints"] = list(CHECKPOINTS[:max(map(len, out["cost_cold"] + out["cost_warm"]), default=0)])
    out["load_avg_1min_end"] = os.getloadavg()[0]
    return out


def profile_step(config: PlannerConfig, k: int = 2, rows: int = 15) -> str:
    """Where one replanning step with ``k`` goals spends its time.

    Returns:
        A cProfile summary of the repository's functions (cumulative time) and a torch.profiler table
        of the aten operators (self CPU time).
    """
    import cProfile
    import io
    import pstats

    scene = load_scene()
    planner = k_goal_planner(scene, config, k)
    occ = blob_occupancy(scene)
    res = planner.step(start_configuration(planner.robot), occ)
    res = planner.step(res.start, occ)
    prof = cProfile.Profile()
    prof.enable()
    res = planner.step(res.start, occ)
    prof.disable()
    text = io.StringIO()
    stats = pstats.Stats(prof, stream=text).sort_stats("cumulative")
    stats.print_stats(r"(services|shared)/", rows)
    lines = [ln for ln in text.getvalue().splitlines() if ln.strip() and "function calls" not in ln]
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as tprof:
        res = planner.step(res.start, occ)
    return (f"one replanning step, K={k}, R={config.stomp.rollouts}, T={config.stomp.waypoints}: cProfile "
            "(cumulative, repository functions)\n" + "\n".join(lines) + "\n\ntorch.profiler (self CPU):\n"
            + tprof.key_averages().table(sort_by="self_cpu_time_total", row_limit=rows))


def peak_memory_mb(k: int, config: PlannerConfig, steps: int = 3) -> float:
    """Peak RSS (MB) of a fresh process that builds the planner and runs ``steps`` steps with ``k`` goals."""
    code = ("import json, resource, sys; from services.planner.bench import _memory_probe; "
            f"_memory_probe({k}, {steps}, json.loads(sys.argv[1]))")
    cfg = {f: getattr(config, f) for f in ("device", "dtype", "threads", "seed", "compile", "fused_cost")}
    cfg["stomp"] = {f: getattr(config.stomp, f) for f in ("rollouts", "waypoints", "iterations")}
    done = subprocess.run([sys.executable, "-c", code, json.dumps(cfg)], capture_output=True, text=True,
                          timeout=600, check=True)
    return float(done.stdout.strip().splitlines()[-1])


def _memory_probe(k: int, steps: int, cfg: dict[str, Any]) -> None:
    config = PlannerConfig(**{**cfg, "stomp": StompConfig(**cfg.get("stomp", {}))})
    scene = load_scene()
    planner = k_goal_planner(scene, config, k)
    occ = blob_occupancy(scene)
    res = planner.step(start_configuration(planner.robot), occ)
    for _ in range(steps):
        res = planner.step(res.start, occ)
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)  # Linux: KiB


def main(argv: list[str] | None = None, prog: str = "foresight bench planner") -> int:
    """Run the planner benchmark; see ``--help``."""
    p = ArgumentParser(prog=prog, description=help_text(__doc__.split("\n\n")[0]))
    p.add_argument("--json", action="store_true", help="print one JSON object (keys K, step_ms, fk_ms, ...)")
    p.add_argument("--k", default="1,2,4,8,16", help="comma-separated goal counts (default 1,2,4,8,16)")
    p.add_argument("--steps", type=int, default=5, help="timed replanning steps per K (median reported)")
    p.add_argument("--rollouts", type=int, default=StompConfig.rollouts)
    p.add_argument("--reuse", type=int, default=StompConfig.reuse, help="rollouts of the previous iteration reused "
                   f"(StompConfig.reuse, default {StompConfig.reuse})")
    p.add_argument("--against", metavar="ROLLOUTS:REUSE", default=None,
                   help="also run STOMP with these rollouts and reuse in the same process and print the ratios of "
                   "step time and final cost (e.g. 16:0, the planner's setting before reuse)")
    p.add_argument("--waypoints", type=int, default=40)
    p.add_argument("--iterations", type=int, default=50)
    p.add_argument("--threads", type=int, default=1, help="torch threads (0: torch's default)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--compile", action=argparse.BooleanOptionalAction, default=True,
                   help="torch.compile the fused cost and STOMP's steps (default on, as PlannerConfig)")
    p.add_argument("--baseline", action="store_true",
                   help="also time the unfused reference cost path (StateCost, eager) in the same process")
    p.add_argument("--profile", action="store_true", help="also print a torch.profiler table of a K=2 step")
    p.add_argument("--memory", action="store_true",
                   help="also measure the peak RSS of a planning process with the largest K of --k")
    p.add_argument("--plot", metavar="PNG", default=None,
                   help="also plan around a blob and draw the paths (e.g. runs/plots/stomp_blob.png)")
    args = p.parse_args(argv)
    with cli_errors(prog):
        try:
            ks = [int(x) for x in args.k.split(",") if x.strip()]
        except ValueError:
            p.error(f"--k: expected comma-separated integers, got {args.k!r}")
        if not ks or min(ks) < 1 or args.steps < 1:
            p.error("--k values and --steps must be >= 1")
        config = PlannerConfig(stomp=StompConfig(rollouts=args.rollouts, waypoints=args.waypoints,
                                                 iterations=args.iterations, reuse=args.reuse),
                               threads=args.threads, device=args.device, compile=args.compile)
        report = run_bench(ks, config, steps=args.steps, progress=not args.json)
        if args.baseline:
            ref = run_bench(ks, dataclasses.replace(config, fused_cost=False, compile=False), steps=args.steps,
                            progress=not args.json)
            report["baseline_step_ms"] = ref["step_ms"]
            report["speedup"] = [round(b / a, 2) for a, b in zip(report["step_ms"], ref["step_ms"], strict=True)]
            report["load_avg_1min_end"] = ref["load_avg_1min_end"]
        if args.against:
            try:
                r_other, n_other = (int(x) for x in args.against.split(":"))
            except ValueError:
                p.error(f"--against: expected ROLLOUTS:REUSE, e.g. 10:5, got {args.against!r}")
            other = dataclasses.replace(config, stomp=dataclasses.replace(config.stomp, rollouts=r_other,
                                                                          reuse=n_other))
            alt = run_bench(ks, other, steps=args.steps, progress=not args.json)
            report["against"] = {"rollouts": r_other, "reuse": n_other, "step_ms": alt["step_ms"],
                                 "final_cost": alt["final_cost"],
                                 "step_ratio": [round(b / a, 3) for a, b in zip(report["step_ms"], alt["step_ms"],
                                                                                strict=True)]}
        if args.memory:
            report["peak_rss_mb"] = round(peak_memory_mb(max(ks), config), 1)
            report["peak_rss_K"] = max(ks)
        if args.json:
            print(strict_json.dumps(report))
        else:
            print(f"planner step ({config.stomp.iterations} STOMP iterations, R={config.stomp.rollouts}, "
                  f"T={config.stomp.waypoints}, "
                  f"{report['threads']} threads, {config.device}, {config.dtype}, fused cost"
                  f"{', compiled' if report['compiled'] else ', eager'}); load avg "
                  f"{report['load_avg_1min']:.2f} -> {report['load_avg_1min_end']:.2f} (other processes share the CPU)")
            vs1 = report.get("time_vs_k1")
            print(f"{'K':>3} {'step ms':>9} {'min ms':>8} {'cpu ms':>8} {'FK ms':>8} {'FK cpu':>8} {'step/FK':>8} "
                  f"{'pk FK ms':>9} {'cost ms':>8} {'share':>6}" + (f" {'t(K)/t(1)':>10}" if vs1 else ""))
            for i, k in enumerate(report["K"]):
                print(f"{k:>3} {report['step_ms'][i]:>9.1f} {report['step_ms_min'][i]:>8.1f} "
                      f"{report['step_cpu_ms'][i]:>8.1f} {report['fk_ms'][i]:>8.1f} {report['fk_cpu_ms'][i]:>8.1f} "
                      f"{report['ratio'][i]:>8.2f} {report['pk_fk_ms'][i]:>9.1f} {report['cost_ms'][i]:>8.1f} "
                      f"{report['cost_ms'][i] / report['step_ms'][i]:>6.2f}" + (f" {vs1[i]:>10.2f}" if vs1 else ""))
            marks = report["checkpoints"][:len(report["cost_warm"][0])]
            print("cost reached against STOMP iterations (best so far / final, summed over the goals; median of the "
                  "timed steps, warm-started from the previous tau_best; cold = the first step, straight lines):")
            print(f"{'K':>3} {'start':>6} " + " ".join(f"{'it ' + str(m):>7}" for m in marks))
            for i, k in enumerate(report["K"]):
                for name in ("cold", "warm"):
                    print(f"{k:>3} {name:>6} " + " ".join(f"{v:>7.3f}" for v in report[f"cost_{name}"][i]))
            if args.baseline:
                print("unfused reference path (StateCost, eager), same process: "
                      + ", ".join(f"K={k}: {b:.1f} ms ({x:.2f}x)" for k, b, x in
                                  zip(report["K"], report["baseline_step_ms"], report["speedup"], strict=True)))
            if args.against:
                a = report["against"]
                print(f"against R={a['rollouts']} reuse={a['reuse']} (same process): step ms, and the least cost "
                      "reached (summed over the goals, median of the warm steps) against the reference above")
                for i, k in enumerate(report["K"]):
                    print(f"{k:>3} {a['step_ms'][i]:>9.1f} ms ({a['step_ratio'][i]:.2f}x the reference)  least cost "
                          f"{a['final_cost'][i]:.4f} vs {report['final_cost'][i]:.4f}")
            print("first Planner construction of each K (incl. compilation): "
                  + ", ".join(f"{s_:.1f} s" for s_ in report["construct_s"]))
            print("cost ms = STOMP's cost calls alone (iterations x one call on K x (R + 1) x T configurations, its "
                  "rollouts of the last plan: FK, 2 trilinear lookups per sphere, self-collision); share = cost ms / "
                  "step ms: the rest is STOMP's own work, its noise, reconnectPrevious (more cost calls) and Python")
            print("FK ms = the fused fk_links on K*R*T configurations x iterations (the planner costs K*(R+1)*T per "
                  "iteration); pk FK ms = pytorch-kinematics forward_kinematics_tensor, same count; cpu = process CPU "
                  "time (with 1 thread: about the time on a core of its own)")
            if args.memory:
                print(f"peak RSS of a K={report['peak_rss_K']} planning process: {report['peak_rss_mb']:.0f} MB")
        if args.profile:
            print(profile_step(config), file=sys.stderr if args.json else sys.stdout)
        if args.plot:
            from .blob_plot import plot_blob

            info = plot_blob(args.plot, config)
            print(f"wrote {info['png']}: human cost straight -> optimised "
                  + ", ".join(f"{n} {a:.2f} -> {b:.3f}" for n, a, b in zip(info["goal_names"], info["human_straight"],
                                                                          info["human_optimised"], strict=True)),
                  file=sys.stderr if args.json else sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
