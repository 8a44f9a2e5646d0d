"""Forward-kinematics timings: pytorch-kinematics vs the fused PR2 kernel (eager and compiled).

``python -m services.planner.fk_bench [--n 1280 5120] [--compile] [--json]`` prints a table of the
median time per call (ms) of

* ``pk``: pytorch-kinematics ``forward_kinematics_tensor`` of the torso -> tool serial chain;
* ``fused``: :meth:`shared.robot.PR2.fk_links` (the fused serial-chain kernel, every link pose);
* ``spheres``: :meth:`shared.robot.PR2.sphere_centers` (fused kernel + one contraction for all spheres);
* ``fused_compiled`` / ``spheres_compiled`` with ``--compile`` (``torch.compile``; the compile time of
  the first call per shape is printed separately),

and the ratio pk / fused. :func:`fk_time_ms` is the function the planner benchmark calls.
Timings on a shared machine are noisy: the median of ``repeats`` calls after a warm-up is reported.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import torch

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.config_tree import ConfigError
from shared.devices import check_device
from shared.robot import PR2
from shared.runtime import cli_errors

__all__ = ["fk_time_ms", "synchronize", "METHODS", "main"]

METHODS = ("pk", "fused", "spheres", "fused_compiled", "spheres_compiled")
_ROBOTS: dict[tuple[str, str, bool], PR2] = {}


def _robot(device: str, dtype: torch.dtype, compiled: bool) -> PR2:
    key = (device, str(dtype), compiled)
    if key not in _ROBOTS:
        _ROBOTS[key] = PR2(device=device, dtype=dtype, compile=compiled)
    return _ROBOTS[key]


def synchronize(device: str | torch.device) -> None:
    """Wait for ``device``'s queued work (a CUDA device; nothing to wait for on the CPU): timings end here."""
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


def _call(method: str, robot: PR2) -> Callable[[torch.Tensor], object]:
    if method == "pk":
        return lambda q: robot.chain.forward_kinematics_tensor(q)
    if method.startswith("fused"):
        return robot.fk_links
    return robot.sphere_centers


def fk_time_ms(n_configs: int, method: str = "spheres", device: str = "cpu", dtype: torch.dtype = torch.float32,
               repeats: int = 20, seed: int = 0, robot: PR2 | None = None, stat: str = "median") -> float:
    """Median wall time (ms) of one batched FK call on ``n_configs`` random configurations.

    Args:
        n_configs: Batch size B (e.g. K goals x R rollouts x T waypoints).
        method: One of :data:`METHODS`.
        device: Torch device.
        dtype: Float dtype.
        repeats: Timed calls (after 2 warm-up calls, which include compilation when compiled).
        seed: Seed of the random configurations (within the joint limits).
        robot: A PR2 to time (default: one cached per device/dtype/compile flag).
        stat: ``"median"`` or ``"min"`` of the timed calls (min is steadier on a busy machine).

    Returns:
        Milliseconds per call.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if n_configs < 1 or repeats < 1:
        raise ValueError("n_configs and repeats must be >= 1")
    compiled = method.endswith("_compiled")
    robot = robot or _robot(device, dtype, compiled)
    g = torch.Generator().manual_seed(seed)
    q = (robot.lower.cpu() + (robot.upper - robot.lower).cpu() * torch.rand(n_configs, robot.dof, generator=g,
                                                                             dtype=robot.dtype)).to(robot.device)
    fn = _call(method, robot)
    with torch.no_grad():
        for _ in range(2):
            fn(q)
        synchronize(robot.device)  # the robot's device: a robot passed in may not be on ``device``
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(q)
            synchronize(robot.device)
            times.append((time.perf_counter() - t0) * 1e3)
    return min(times) if stat == "min" else statistics.median(times)


def main(argv: list[str] | None = None, prog: str = "python -m services.planner.fk_bench") -> int:
    """Print the FK timing table."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[1280, 5120], help="batch sizes")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=0, help="torch intra-op threads (0: torch's default)")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--compile", action="store_true", help="also time the torch.compile'd kernels")
    parser.add_argument("--stat", default="median", choices=("median", "min"), help="statistic of the timed calls")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    args = parser.parse_args(argv)
    try:
        check_device(args.device, "--device")
    except ConfigError as exc:
        parser.error(str(exc))
    if args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    if min(args.n) < 1:
        parser.error(f"--n: each batch size must be at least 1, got {min(args.n)}")
    if args.threads < 0:
        parser.error(f"--threads must be >= 0 (0: torch's default), got {args.threads}")
    with cli_errors(prog):
        return _table(args)


def _table(args: argparse.Namespace) -> int:
    """Time every method at each batch size of :func:`main`'s checked options and print them."""
    if args.threads:
        torch.set_num_threads(args.threads)
    methods = [m for m in METHODS if args.compile or not m.endswith("_compiled")]
    rows: dict[str, list[float]] = {m: [] for m in methods}
    compile_s: dict[str, list[float]] = {}
    for n in args.n:
        for m in methods:
            if m.endswith("_compiled"):
                robot = _robot(args.device, torch.float32, True)
                q = robot.lower.expand(n, -1).clone()
                t0 = time.perf_counter()
                _call(m, robot)(q)
                compile_s.setdefault(m, []).append(time.perf_counter() - t0)
            rows[m].append(fk_time_ms(n, m, device=args.device, repeats=args.repeats, stat=args.stat))
    if args.json:
        print(strict_json.dumps({"n": args.n, "threads": torch.get_num_threads(), "stat": args.stat,
                          **{f"{m}_ms": v for m, v in rows.items()},
                          **{f"{m}_first_call_s": v for m, v in compile_s.items()}}))
        return 0
    print(f"FK time per call (ms, {args.stat} of {args.repeats}; {torch.get_num_threads()} threads, {args.device}, "
          "float32)")
    print(f"{'method':<18}" + "".join(f"{n:>12}" for n in args.n))
    for m in methods:
        print(f"{m:<18}" + "".join(f"{v:>12.3f}" for v in rows[m]))
    print(f"{'pk / fused':<18}" + "".join(f"{p / f:>12.1f}" for p, f in zip(rows["pk"], rows["fused"], strict=True)))
    print(f"{'pk / spheres':<18}" + "".join(f"{p / f:>12.1f}" for p, f in zip(rows["pk"], rows["spheres"],
                                                                            strict=True)))
    for m, v in compile_s.items():
        print(f"first call of {m} (compile): " + ", ".join(f"{s:.1f} s" for s in v))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
