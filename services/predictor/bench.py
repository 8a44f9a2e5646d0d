"""``foresight bench predictor``: time one prediction update (new pose -> encoded OccupancyGrid message).

Streams demonstrations of the synthetic library through :class:`PredictorCore` on a 64 x 64 x 64
grid and reports the median (and spread) of the whole update: incremental log-likelihood, posterior,
occupancy over the union of the swept volumes, quantisation and msgpack encoding. For comparison, the
same update done densely (``(M,) @ (M, V)`` over every voxel, then ``OccupancyGrid.from_dense``) is
timed in the same process, and the ``current`` (posture-only) method too.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.protocol import OccupancyGrid, encode
from shared.runtime import cli_errors
from shared.scene import Grid, Scene, load_scene

from .core import PredictorConfig, PredictorCore
from .gmm import GMMConfig, posterior_from_log_likelihood
from .model import PredictionModel
from .train import TrainConfig, default_library, train_model
from .volumes import DEFAULT_VOLUME, VOLUMES

__all__ = ["bench_grid", "run_bench", "main"]


def bench_grid(scene: Scene, n: int = 64) -> Grid:
    """An ``n x n x n`` grid from the scene grid's lower corner, covering its largest extent."""
    res = float(np.max(scene.grid.max - scene.grid.min)) / n
    return Grid(scene.grid.min.copy(), scene.grid.min + n * res, res)


def _meta(i: int) -> dict:
    return {"stamp": 0.0, "tick": -1, "tick_last": True, "demo_id": 0, "index": i}


def run_bench(model: PredictionModel, scene: Scene, poses: list[np.ndarray], repeats: int = 1) -> dict:
    """Time every update of ``poses`` (each a ``(T, 12)`` demonstration) ``repeats`` times.

    Returns:
        A dict of figures (milliseconds unless named otherwise).
    """
    core = PredictorCore(model, scene)
    cur = PredictorCore(model, scene, PredictorConfig(method="current"))
    dense_vol = model.volumes.reshape(model.n_classes, -1).astype(np.float32)  # (M, V) baseline
    t_all, t_ll, t_occ, t_enc, t_dense, t_cur, sizes, nnz = [], [], [], [], [], [], [], []
    for _ in range(repeats):
        for demo in poses:
            core.reset(0)
            cur.reset(0)
            for i, f in enumerate(demo):
                t0 = time.perf_counter()
                res = core.update(f, i)
                t1 = time.perf_counter()
                data = encode(res.to_message(**_meta(i)))
                t2 = time.perf_counter()
                t_all.append(t2 - t0)
                t_enc.append(t2 - t1)
                sizes.append(len(data))
                nnz.append(int(np.count_nonzero(res.values >= 0.5 / 255)))
                # split of core.update: likelihood + posterior vs occupancy
                t3 = time.perf_counter()
                post = posterior_from_log_likelihood(core.log_likelihood())
                t4 = time.perf_counter()
                core.occupancy_for(post, i)
                t5 = time.perf_counter()
                t_ll.append((t1 - t0) - (t5 - t4))
                t_occ.append(t5 - t4)
                del t3
                # baseline: dense occupancy over every voxel, then from_dense
                t6 = time.perf_counter()
                occ = (post.astype(np.float32) @ dense_vol).reshape(model.grid.dims)
                encode(OccupancyGrid.from_dense(occ, model.grid.min, model.grid.resolution, method="prediction",
                                                **_meta(i)))
                t7 = time.perf_counter()
                t_dense.append(t7 - t6)
                t8 = time.perf_counter()
                encode(cur.update(f, i).to_message(**_meta(i)))
                t_cur.append(time.perf_counter() - t8)

    def ms(x: list[float], q: float = 50) -> float:
        return float(np.percentile(np.asarray(x) * 1e3, q))

    return {
        "grid_dims": list(model.grid.dims), "resolution": model.grid.resolution, "classes": model.n_classes,
        "gaussians": int(model.weights.shape[1]), "union_voxels": int(len(core.support)), "updates": len(t_all),
        "update_ms_median": ms(t_all), "update_ms_p90": ms(t_all, 90), "update_ms_max": ms(t_all, 100),
        "likelihood_ms_median": ms(t_ll), "occupancy_ms_median": ms(t_occ), "encode_ms_median": ms(t_enc),
        "dense_baseline_ms_median": ms(t_dense), "speedup_vs_dense": ms(t_dense) / ms(t_all),
        "current_method_ms_median": ms(t_cur), "message_bytes_median": float(np.median(sizes)),
        "nonzero_voxels_median": float(np.median(nnz)), "volume": model.volume_method,
    }


DESCRIPTION = """Benchmark the predictor: one new pose -> encoded OccupancyGrid message, on a 64x64x64 grid.
Without --model it trains a quick model on the synthetic library first (20 Gaussians, 20 EM iterations;
the fit quality does not change the cost of an update)."""


def main(argv: list[str] | None = None, prog: str = "foresight bench predictor") -> int:
    """``foresight bench predictor``; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=DESCRIPTION)
    parser.add_argument("--model", metavar="PATH", default=None,
                        help="benchmark this model file (its own grid) instead of a quick 64^3 model")
    parser.add_argument("--grid", type=int, default=64, help="voxels per axis of the quick model's grid (default 64)")
    parser.add_argument("--demos", type=int, default=8, help="demonstrations streamed (default 8, 100 poses each)")
    parser.add_argument("--repeats", type=int, default=2, help="passes over the demonstrations (default 2)")
    parser.add_argument("--volume", choices=VOLUMES, default=DEFAULT_VOLUME,
                        help=f"volume method of the quick model (default: {DEFAULT_VOLUME})")
    parser.add_argument("--json", action="store_true", help="print one JSON object (key update_ms_median, ...)")
    args = parser.parse_args(argv)
    for name in ("grid", "demos", "repeats"):  # before the quick model's training (about a minute)
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    with cli_errors(prog):
        scene = load_scene(None)
        lib = default_library()
        if args.model:
            model = PredictionModel.load(Path(args.model))
            scene = load_scene(None)
        else:
            grid = bench_grid(scene, args.grid)
            sc = Scene(scene.name, scene.human, scene.robot, scene.boxes, scene.cups, grid, scene.workspace,
                       scene.source)
            # tau does not change the cost of an update: a fixed one spares the cross-validation
            cfg = TrainConfig(gmm=GMMConfig(n_components=20, max_iter=20), resolution=None, temperature=150.0,
                              volume=args.volume)
            model = train_model(lib, sc, cfg, progress=not args.json)
        step = max(1, len(lib.demos) // max(args.demos, 1))
        poses = [d.features for d in lib.demos[::step][: args.demos]]
        res = run_bench(model, scene, poses, args.repeats)
        if args.json:
            print(strict_json.dumps(res))
        else:
            print(f"{model.volume_method} volumes: predictor update on a {'x'.join(map(str, res['grid_dims']))} "
                  f"grid at {res['resolution']:.4f} m, "
                  f"{res['classes']} classes x {res['gaussians']} Gaussians, {res['union_voxels']} voxels in the "
                  f"union of the swept volumes, {res['updates']} updates (shared machine: timings are noisy)")
            rows = [("update: pose -> encoded OccupancyGrid (median)", res["update_ms_median"], "ms"),
                    ("  p90", res["update_ms_p90"], "ms"), ("  max", res["update_ms_max"], "ms"),
                    ("  likelihood + posterior (median)", res["likelihood_ms_median"], "ms"),
                    ("  occupancy over the union (median)", res["occupancy_ms_median"], "ms"),
                    ("  quantise + encode (median)", res["encode_ms_median"], "ms"),
                    ("baseline: dense (M,V) product + from_dense + encode", res["dense_baseline_ms_median"], "ms"),
                    ("speed-up vs dense baseline", res["speedup_vs_dense"], "x"),
                    ("method=current: posture voxels + encode (median)", res["current_method_ms_median"], "ms"),
                    ("message size (median)", res["message_bytes_median"] / 1e3, "kB"),
                    ("non-zero voxels (median)", res["nonzero_voxels_median"], "")]
            for name, val, unit in rows:
                print(f"{name:<56} {val:10.3f} {unit}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
