"""``foresight bench viz``: the executor's CPU time per occupancy update of the Foxglove scene, SDK vs JSON.

One occupancy update is what the executor's scene thread does with a received ``OccupancyGrid``: build the
picture of its voxels (p >= 0.05), encode it and write it to the run's MCAP log. Two ways, in one process, one
thread, interleaved update by update (the same message, so machine load falls on both alike):

* ``sdk`` (what the executor does now): :meth:`SceneStream.draw <shared.foxglove.stream.SceneStream.draw>`
  builds a ``foxglove.PointCloud`` (:meth:`SceneBuilder.occupancy_cloud
  <shared.foxglove.scene.SceneBuilder.occupancy_cloud>`) and encodes it as protobuf in the SDK's Rust core;
  :meth:`McapLog.write_viz <shared.recording.writer.McapLog.write_viz>` writes it;
* ``json`` (the baseline): the JSON path this replaced (``shared/recording/foxglove.py``
  ``SceneBuilder.occupancy_cubes``, ``shared/recording/json_slices.py`` ``dumps_sliced`` and
  ``McapLog.write_json`` of ``shared/recording/writer.py``, git 4b212ba..a460722), kept here only as the
  benchmark's baseline: one ``foxglove.CubePrimitive`` dict per voxel in a ``foxglove.SceneUpdate``, JSON text
  encoded 200 cubes per ``json.dumps`` call, written to an MCAP file of the same chunk size and compression.

The occupancies are seeded blobs (a torso and a reaching arm) on an ``n^3`` grid, scaled so that about
``--voxels`` voxels are drawn. Prints per update the CPU time of the thread (median, p99), the wall time, the
bytes of the message and of the (zstd) file, and the ratio of the baseline's CPU time to each; both files are
read back and the cubes of each JSON update counted against the points of its cloud. The target: the SDK
path at least 5x less CPU than the JSON path.
"""

from __future__ import annotations

import io
import json
import sys
import tempfile
import threading
import time
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer

from shared.arguments import ArgumentParser
from shared.protocol import Keys, OccupancyGrid
from shared.recording.direct_file import DirectFile
from shared.recording.schemas import PROFILE
from shared.recording.writer import McapLog
from shared.scene import Scene, load_scene

from .decode import read_scene
from .scene import SceneBuilder, probability_color
from .stream import SceneStream

__all__ = ["TARGET_RATIO", "bench_occupancies", "json_occupancy", "dumps_sliced", "JsonLog", "run_bench", "main"]

TARGET_RATIO = 5.0
"""The SDK path's CPU time per update is to be at least this many times lower than the JSON path's."""

TOPIC = "/viz/occupancy"

# ----------------------------------------------------------------------------------------------
# the occupancies


def bench_occupancies(scene: Scene, updates: int, voxels: int, seed: int = 0, n: int = 64) -> list[OccupancyGrid]:
    """``updates`` seeded occupancies on an ``n^3`` grid from the scene grid's lower corner, ~``voxels`` drawn each.

    Each is a blob - a torso and an arm reaching from its shoulder in a random direction, with 10 % noise - whose
    probability saturates at 0.95 and falls off smoothly: about ``voxels`` voxels reach p >= 0.05 (what is drawn),
    and a wider shell of lower, non-zero ones is sent too (as the predictor's are).
    """
    rng = np.random.default_rng(seed)
    res = float(np.max(scene.grid.max - scene.grid.min)) / n
    origin = scene.grid.min.astype(np.float64)
    xs, ys, zs = (origin[d] + res * (np.arange(n) + 0.5) for d in range(3))  # voxel centres per axis
    middle = origin + res * n / 2
    out = []
    for i in range(updates):
        torso = middle + rng.uniform(-0.2, 0.2, 3)
        shoulder = torso + np.array([0.0, 0.0, 0.25])
        reach = rng.normal(size=3)
        reach *= rng.uniform(0.4, 0.6) / np.linalg.norm(reach)
        blobs = [(torso, np.array([0.12, 0.12, 0.3]), 1.0)]
        blobs += [(shoulder + s * reach, np.full(3, 0.06), 0.8) for s in np.linspace(0.0, 1.0, 6)]
        f = np.zeros((n, n, n))
        for mu, sigma, w in blobs:  # separable: three 1-D Gaussians, broadcast
            gx, gy, gz = (np.exp(-0.5 * ((a - m) / s) ** 2) for a, m, s in zip((xs, ys, zs), mu, sigma, strict=True))
            f += w * gx[:, None, None] * gy[None, :, None] * gz[None, None, :]
        f *= 1.0 + 0.1 * rng.standard_normal(f.shape)
        k = min(max(1, voxels), f.size)
        fk = max(float(np.partition(f.ravel(), -k)[-k]), 1e-12)  # the k-th largest: p(fk) = 0.05
        p = 0.95 * (1.0 - np.exp(np.log(1.0 - 0.05 / 0.95) * np.clip(f, 0.0, None) / fk))
        out.append(OccupancyGrid.from_dense(p, origin, res, stamp=0.2 * i, tick=i, tick_last=True, demo_id=0,
                                            index=i, method="prediction"))
    return out


# ----------------------------------------------------------------------------------------------
# the baseline: the JSON path this replaced (git 4b212ba..a460722), kept only as the benchmark's baseline


def _time_of(seconds: float) -> dict[str, int]:
    ns = max(0, int(round(seconds * 1e9)))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _v(p: Any) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def _c(rgba: Any) -> dict[str, float]:
    return {"r": float(rgba[0]), "g": float(rgba[1]), "b": float(rgba[2]), "a": float(rgba[3])}


_IDENTITY_Q = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def _pose_at(p: Any) -> dict[str, Any]:
    return {"position": _v(p), "orientation": dict(_IDENTITY_Q)}


def _entity(entity_id: str, stamp: float, **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    ent: dict[str, Any] = {"timestamp": _time_of(stamp), "frame_id": "world", "id": entity_id,
                           "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False, "metadata": []}
    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        ent[kind] = primitives.get(kind, [])
    return ent


def json_occupancy(occ: OccupancyGrid, stamp: float, min_probability: float = 0.05,
                   max_voxels: int = 20000) -> dict[str, Any]:
    """The old ``SceneBuilder.occupancy_cubes``: a JSON-ready ``foxglove.SceneUpdate``, one cube per drawn voxel."""
    p = occ.values.astype(np.float64) / 255.0
    keep = np.flatnonzero(p >= min_probability)
    if keep.size > max_voxels:
        keep = keep[np.argsort(-p[keep], kind="stable")[:max_voxels]]
    dims = tuple(int(d) for d in occ.dims)
    ijk = np.stack(np.unravel_index(occ.indices[keep].astype(np.int64), dims), axis=-1)
    centers = occ.origin + occ.resolution * (ijk + 0.5)
    colors = probability_color(p[keep])
    size = _v([occ.resolution] * 3)
    cubes = [{"pose": _pose_at(c), "size": size, "color": _c(tuple(col))} for c, col in zip(centers, colors,
                                                                                             strict=True)]
    return {"deletions": [], "entities": [_entity("occupancy", stamp, cubes=cubes)]}


_SLICE = 200


def dumps_sliced(obj: Any) -> str:
    """The old ``dumps_sliced``: ``json.dumps(obj, separators=(",", ":"))``, long lists 200 items per call."""
    if isinstance(obj, dict) and all(isinstance(k, str) for k in obj):
        return "{" + ",".join(_plain(k) + ":" + dumps_sliced(v) for k, v in obj.items()) + "}"
    if isinstance(obj, list) and len(obj) <= 8:
        return "[" + ",".join(dumps_sliced(v) for v in obj) + "]"
    if isinstance(obj, list) and len(obj) > _SLICE:
        return "[" + ",".join(_plain(obj[i:i + _SLICE])[1:-1] for i in range(0, len(obj), _SLICE)) + "]"
    return _plain(obj)


def _plain(obj: Any) -> str:
    return json.dumps(obj, separators=(",", ":"))


_SCENE_UPDATE_SCHEMA = {"title": "foxglove.SceneUpdate", "type": "object"}
"""A stand-in for the old channel's JSON Schema (registered once; no part of an update's cost)."""


class JsonLog:
    """The old ``McapLog.write_json`` on one JSON channel: the same file, chunk size, compression and flushing."""

    def __init__(self, path: Path, chunk_size: int = 256 * 1024, flush_period_s: float = 1.0) -> None:
        self._file = DirectFile(path)
        self._writer = Writer(typing.cast(io.BufferedWriter, self._file), chunk_size=chunk_size,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="foresight bench viz (JSON baseline)")
        self._lock = threading.RLock()
        self._channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.flush_period_s = flush_period_s
        self._last_flush = time.monotonic()

    def write_json(self, topic: str, obj: dict[str, Any], log_time: int) -> int:
        """Encode and write ``obj``; returns the message's bytes."""
        data = dumps_sliced(obj).encode()  # outside the lock, as the old writer did
        with self._lock:
            if topic not in self._channels:
                sid = self._writer.register_schema(name="foxglove.SceneUpdate", encoding="jsonschema",
                                                   data=json.dumps(_SCENE_UPDATE_SCHEMA).encode())
                self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="json",
                                                                      schema_id=sid)
            self._writer.add_message(channel_id=self._channels[topic], log_time=log_time, data=data,
                                     publish_time=log_time, sequence=self.counts.get(topic, 0))
            self.counts[topic] = self.counts.get(topic, 0) + 1
            if time.monotonic() - self._last_flush >= self.flush_period_s:
                self._writer.flush()
                self._last_flush = time.monotonic()
        return len(data)

    def close(self) -> None:
        """Write the summary and the footer."""
        self._writer.finish()
        self._file.close()


# ----------------------------------------------------------------------------------------------
# the benchmark


def _timed(fn: Callable[[], int]) -> tuple[int, int, int]:
    """``(thread CPU ns, wall ns, bytes)`` of ``fn()`` (which returns the bytes it wrote)."""
    c0, w0 = time.thread_time_ns(), time.perf_counter_ns()
    n = fn()
    return time.thread_time_ns() - c0, time.perf_counter_ns() - w0, n


def run_bench(scene: Scene, occupancies: list[OccupancyGrid], workdir: Path, warmup: int = 2) -> dict[str, Any]:
    """Time each occupancy's update on both paths (interleaved), then read both files back.

    Returns:
        ``{"json": ..., "sdk": ...}``: per path the per-update ``cpu_ms``, ``wall_ms``, ``bytes``, the drawn
        ``items`` read back from its file (cubes, points), ``file_bytes`` and ``file_updates`` (the updates the
        file holds: the timed ones and the warm-ups).
    """
    stream = SceneStream(SceneBuilder(scene), viz_period_s=0.0)
    json_path, sdk_path = workdir / "json.mcap", workdir / "sdk.mcap"
    old = JsonLog(json_path)
    new = McapLog(sdk_path, Keys(), builder=None, viz_thread=False)
    t0 = time.time_ns()

    def baseline(occ: OccupancyGrid, log_time: int) -> int:
        return old.write_json(TOPIC, json_occupancy(occ, log_time / 1e9), log_time)

    def sdk(occ: OccupancyGrid, log_time: int) -> int:
        size = 0
        for m in stream.draw(occ, log_time):
            new.write_viz(m)
            size += len(m.data)
        return size

    paths = {"json": baseline, "sdk": sdk}
    runs: dict[str, list[tuple[int, int, int]]] = {name: [] for name in paths}
    warmup = len(occupancies[:warmup])  # fewer occupancies than warm-ups: each is written once untimed
    for i, occ in enumerate(occupancies[:warmup] + occupancies):
        log_time = t0 + i * 200_000_000
        order = list(paths) if i % 2 == 0 else list(reversed(paths))  # neither always goes first
        for name in order:
            r = _timed(lambda fn=paths[name], o=occ, t=log_time: fn(o, t))
            if i >= warmup:
                runs[name].append(r)
    old.close()
    new.close()
    items = {"json": [len(r.message["entities"][0]["cubes"]) for r in read_scene(json_path, {TOPIC})],
             "sdk": [len(r.message.data) // r.message.point_stride for r in read_scene(sdk_path, {TOPIC})]}
    out: dict[str, Any] = {}
    for name, rs in runs.items():
        a = np.array(rs, dtype=np.float64)
        out[name] = {"cpu_ms": (a[:, 0] / 1e6).tolist(), "wall_ms": (a[:, 1] / 1e6).tolist(),
                     "bytes": a[:, 2].astype(int).tolist(), "items": items[name][warmup:],
                     "file_bytes": (json_path if name == "json" else sdk_path).stat().st_size,
                     "file_updates": warmup + len(rs)}
    return out


def _summary(res: dict[str, Any]) -> dict[str, Any]:
    n = res["file_updates"]  # the file holds the warm-up updates too
    return {"cpu_ms_p50": float(np.median(res["cpu_ms"])), "cpu_ms_p99": float(np.percentile(res["cpu_ms"], 99)),
            "wall_ms_p50": float(np.median(res["wall_ms"])), "wall_ms_p99": float(np.percentile(res["wall_ms"], 99)),
            "bytes_per_update": float(np.mean(res["bytes"])), "file_bytes_per_update": res["file_bytes"] / max(1, n),
            "items_p50": float(np.median(res["items"])) if res["items"] else 0.0}


def main(argv: list[str] | None = None, prog: str = "foresight bench viz") -> int:
    """Run the benchmark; returns the exit status (1 if the two paths drew different voxels)."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--updates", type=int, default=50, help="occupancy updates timed (default 50)")
    parser.add_argument("--voxels", type=int, default=3000,
                        help="voxels drawn per update, p >= 0.05 (default 3000, as the demo's occupancies)")
    parser.add_argument("--grid", type=int, default=64, help="voxels per axis of the grid (default 64)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the occupancies")
    parser.add_argument("--json-out", type=Path, default=None, help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    if args.updates < 1 or args.voxels < 1 or args.grid < 1:
        parser.error("--updates, --voxels and --grid must be positive")
    scene = load_scene()
    occs = bench_occupancies(scene, args.updates, args.voxels, args.seed, args.grid)
    with tempfile.TemporaryDirectory(prefix="foresight-bench-viz-") as tmp:
        res = run_bench(scene, occs, Path(tmp))
    summ = {name: _summary(r) for name, r in res.items()}
    base = summ["json"]["cpu_ms_p50"]
    ratio = base / max(summ["sdk"]["cpu_ms_p50"], 1e-9)
    same = res["json"]["items"] == res["sdk"]["items"]
    print(f"{prog}: {args.updates} occupancy updates, {args.grid}^3 grid, {summ['sdk']['items_p50']:.0f} voxels "
          f"drawn (median), one thread, build + encode + write to MCAP (zstd)")
    print(f"{'':40}{'CPU ms p50':>11}{'p99':>8}{'wall ms p50':>13}{'p99':>8}{'KB/update':>11}"
          f"{'file KB/update':>15}{'CPU vs json':>13}")
    names = {"json": "json: cubes as JSON (baseline, replaced)", "sdk": "sdk: PointCloud protobuf (executor)"}
    for name, s in summ.items():
        print(f"{names[name]:40}{s['cpu_ms_p50']:>11.2f}{s['cpu_ms_p99']:>8.2f}{s['wall_ms_p50']:>13.2f}"
              f"{s['wall_ms_p99']:>8.2f}{s['bytes_per_update'] / 1e3:>11.1f}{s['file_bytes_per_update'] / 1e3:>15.1f}"
              f"{base / max(s['cpu_ms_p50'], 1e-9):>12.1f}x")
    verdict = "met" if ratio >= TARGET_RATIO else "NOT met"
    print(f"target: sdk >= {TARGET_RATIO:g}x less CPU per update than json: {verdict} ({ratio:.1f}x); "
          f"drawn voxels read back: {'equal' if same else 'DIFFERENT'} on both paths")
    if args.json_out is not None:
        args.json_out.parent.mkdir(parents=True, exist_ok=True)
        args.json_out.write_text(json.dumps({"updates": args.updates, "voxels": args.voxels, "grid": args.grid,
                                             "seed": args.seed, "target_ratio": TARGET_RATIO, "cpu_ratio_p50": ratio,
                                             "summary": summ, "paths": res}, indent=1))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
