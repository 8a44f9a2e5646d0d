"""``foresight bench codec``: encode and decode of each wire message against bare msgpack, in one process.

What the codec adds to msgpack is its checks: every field named and typed, every array's dtype, shape and
finiteness, the bounds of ``shared/protocol/limits.py``, the message's own invariants (docs/protocol.md). This
bench shows what they cost. Each message is one the services send in a run (a pose, a posterior, the robot's
state, an occupancy grid of about ``--voxels`` voxels, a plan of K = 2 goals at 40 and at 101 waypoints, a
keypoint frame), built from a seeded generator. Four calls per message:

* ``encode``: :func:`~shared.protocol.encode` of the message;
* ``pack`` (the baseline): ``msgpack.packb`` of the plain structure the encoded bytes hold;
* ``decode``: :func:`~shared.protocol.decode` of the bytes, checks included;
* ``unpack`` (the baseline): ``msgpack.unpackb`` of the bytes, no check, no array built.

Each figure is the best of ``--repeats`` means over ``--loops`` calls (us per call), every repeat timing every call
of every message once (a slow moment of the machine falls on one repeat of all of them); the ratios are the
codec's time over msgpack's. Every message is checked to decode to bytes that encode back identically.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import msgpack
import numpy as np

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.runtime import cli_errors

from .codec import decode, encode
from .messages import ClassPosterior, HumanKeypoints, HumanPose, Message, OccupancyGrid, Plan, RobotState

__all__ = ["bench_messages", "run_bench", "main"]

JOINTS = [f"joint_{i}" for i in range(8)]


def bench_messages(voxels: int = 1500, seed: int = 0) -> list[tuple[str, Message]]:
    """The benchmark's messages, named: one of each kind a run sends (plans at 40 and 101 waypoints)."""
    rng = np.random.default_rng(seed)
    dims = np.array([48, 48, 40], dtype=np.int32)
    cells = int(np.prod(dims))
    indices = np.sort(rng.choice(cells, size=min(voxels, cells), replace=False)).astype(np.uint32)

    def plan(t: int) -> Plan:
        cost = rng.random(2) + 1.0
        return Plan(stamp=1.0, tick=3, step=3, goal_names=["blue_cup", "red_cup"], joint_names=list(JOINTS), dt=0.1,
                    chosen=1, planning_ms=60.0, occupancy_tick=3, occupancy_index=30,
                    trajectories=rng.normal(0.0, 0.5, (2, t, 8)).astype(np.float32), cost_smoothness=cost,
                    cost_obstacle=cost * 0.1, cost_human=cost * 0.5, cost_total=cost * 1.6, valid=np.ones(2, bool))

    post = rng.random(8)
    return [
        ("HumanPose", HumanPose(stamp=1.0, tick=3, tick_last=True, demo_id=1, index=30,
                                features=rng.normal(0.0, 0.3, 12))),
        ("ClassPosterior", ClassPosterior(stamp=1.0, tick=3, demo_id=1, index=30,
                                          class_names=[f"class_{m}" for m in range(8)], posterior=post / post.sum(),
                                          log_likelihood=rng.normal(-200.0, 30.0, 8))),
        ("RobotState", RobotState(stamp=1.0, tick=3, joint_names=list(JOINTS), goal=1, reached=False, holding=False,
                                  reason="", q=rng.normal(0.0, 0.5, 8), qd=rng.normal(0.0, 0.1, 8))),
        (f"OccupancyGrid ({indices.size} voxels)", OccupancyGrid(
            stamp=1.0, tick=3, tick_last=True, demo_id=1, index=30, method="prediction", resolution=0.05,
            origin=np.array([-0.2, -1.2, 0.0]), dims=dims, indices=indices,
            values=rng.integers(1, 256, indices.size).astype(np.uint8))),
        ("Plan (K 2, T 40)", plan(40)),
        ("Plan (K 2, T 101)", plan(101)),
        ("HumanKeypoints (17)", HumanKeypoints(stamp=1.0, tick=-1, frame=30, frame_id="recorder",
                                               names=[f"point_{j}" for j in range(17)],
                                               positions=rng.normal(0.0, 0.5, (17, 3)))),
    ]


def _mean_us(fn: Callable[[], Any], loops: int) -> float:
    start = time.perf_counter()
    for _ in range(loops):
        fn()
    return (time.perf_counter() - start) / loops * 1e6


def _calls(msg: Message) -> dict[str, Callable[[], Any]]:
    """The four timed calls of one message, after checking its round trip."""
    data = encode(msg)
    if encode(decode(data, type(msg))) != data:
        raise AssertionError(f"{msg.TYPE}: decoding and encoding again changed its bytes")
    plain = msgpack.unpackb(data)
    return {"encode": lambda: encode(msg), "pack": lambda: msgpack.packb(plain),
            "decode": lambda: decode(data, type(msg)), "unpack": lambda: msgpack.unpackb(data)}


def run_bench(loops: int = 2000, repeats: int = 5, voxels: int = 1500, seed: int = 0,
              progress: Callable[[str], None] = lambda _s: None) -> list[dict[str, Any]]:
    """One row per message: name, bytes, the four times (us) and the codec-over-msgpack ratios.

    Each repeat times every call of every message once, so that a slow moment of the machine falls on one repeat
    of all of them, and the best of the repeats is kept.

    Raises:
        AssertionError: If a message does not decode to bytes that encode back identically.
    """
    msgs = bench_messages(voxels, seed)
    calls = {name: _calls(msg) for name, msg in msgs}
    best = {name: dict.fromkeys(c, float("inf")) for name, c in calls.items()}
    for r in range(repeats):
        progress(f"repeat {r + 1} of {repeats} ...")
        for name, c in calls.items():
            for call, fn in c.items():
                best[name][call] = min(best[name][call], _mean_us(fn, loops))
    rows = []
    for name, msg in msgs:
        t = best[name]
        rows.append({"message": name, "bytes": len(encode(msg)), **t, "encode_ratio": t["encode"] / t["pack"],
                     "decode_ratio": t["decode"] / t["unpack"]})
    return rows


def main(argv: list[str] | None = None, prog: str = "foresight bench codec") -> int:
    """Print the table (or ``--json``); returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--loops", type=int, default=2000, help="calls per timing (default: 2000)")
    parser.add_argument("--repeats", type=int, default=5, help="timings per call, the best kept (default: 5)")
    parser.add_argument("--voxels", type=int, default=1500, help="voxels of the occupancy grid (default: 1500)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the messages' values (default: 0)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    args = parser.parse_args(argv)
    with cli_errors(prog):
        for name in ("loops", "repeats", "voxels"):
            if getattr(args, name) < 1:
                parser.error(f"--{name} must be >= 1, got {getattr(args, name)}")
        say = (lambda _s: None) if args.json else (lambda s: print(s, file=sys.stderr, flush=True))
        rows = run_bench(args.loops, args.repeats, args.voxels, args.seed, say)
        if args.json:
            print(strict_json.dumps({"loops": args.loops, "repeats": args.repeats, "rows": rows}))
            return 0
        print(f"wire codec against bare msgpack, us per call (best of {args.repeats} x {args.loops}); ratio = codec "
              "/ msgpack")
        print(f"{'message':<30}{'bytes':>8}{'encode':>9}{'pack':>8}{'ratio':>7}{'decode':>9}{'unpack':>8}{'ratio':>7}")
        for r in rows:
            print(f"{r['message']:<30}{r['bytes']:>8.0f}{r['encode']:>9.1f}{r['pack']:>8.1f}{r['encode_ratio']:>7.1f}"
                  f"{r['decode']:>9.1f}{r['unpack']:>8.1f}{r['decode_ratio']:>7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
