"""``foresight bench tracker-live``: how late the tracker's poses come, as a process behind a router, at each rate.

A router and ``foresight tracker`` run as processes (loopback, scouting off). This process plays one library
demonstration as a sensor at each rate of ``--rates`` would send it (the human model's joint positions, ``--rest-s``
of rest before and after, the recorded motion sampled at the rate), on the keypoints key in real time, each frame
stamped when sent, and takes the poses and markers back. Per rate it prints the frames sent, the poses received and
each pose's delay (arrival minus stamp: median and max), and the median against the first rate's (the baseline, 30
Hz: the library's rate) as a ratio. The max includes ``pre_s``: a reach's first poses are frames 0.3 s old. Before
the tracker queued its frames and fitted at most ``max_fit_hz`` of them (docs/keypoints.md), a review's script
measured 2.43 s median at 120 Hz and 7.08 s at 240 Hz on this 2-core machine.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from services.processes import ServiceProcess, free_port
from shared.arguments import ArgumentParser
from shared.config import ZenohConfig
from shared.human import HumanModel
from shared.keypoints.bench import source_library
from shared.keypoints.fit import POINT_NAMES
from shared.library import MotionLibrary
from shared.protocol import AT_REST, DemoMarker, HumanKeypoints, HumanPose, Keys
from shared.runtime import cli_errors
from shared.transport import TypedPublisher, open_session, subscribe

from .bench import sample_at
from .core import LIBRARY_RATE_HZ

__all__ = ["main"]


def _frames(feats: np.ndarray, rate_hz: float, rest_s: float, model: HumanModel) -> np.ndarray:
    """``(N, J, 3)``: the demonstration with rest before and after, as a sensor at ``rate_hz`` sees it."""
    rest = int(round(rest_s * LIBRARY_RATE_HZ))
    padded = np.concatenate([np.repeat(feats[:1], rest, 0), feats, np.repeat(feats[-1:], rest, 0)])
    recorded = np.arange(len(padded)) / LIBRARY_RATE_HZ
    return model.joint_positions(sample_at(np.arange(0.0, recorded[-1] + 1e-9, 1.0 / rate_hz), recorded, padded))


def main(argv: list[str] | None = None, prog: str = "foresight bench tracker-live") -> int:
    """Run the benchmark; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--rates", default="30,60,120,240", help="sensor rates (Hz), comma-separated; the first is "
                        "the baseline")
    parser.add_argument("--library", default=None, help="motion library (default: the synthetic one, seed 0)")
    parser.add_argument("--demo", type=int, default=0, help="the demonstration played (the library's n-th)")
    parser.add_argument("--rest-s", type=float, default=1.5, help="rest before and after the reach (s)")
    parser.add_argument("--out", default=None, help="keep the processes' logs in this directory (default: a "
                        "temporary one, removed at the end; kept, and named, if the bench fails)")
    args = parser.parse_args(argv)
    try:
        rates = [float(r) for r in args.rates.split(",") if r.strip()]
    except ValueError:
        parser.error(f"--rates: {args.rates!r} is not a comma-separated list of numbers")
    if not rates or not all(0 < r <= 1000 for r in rates):
        parser.error(f"--rates: each rate must be in (0, 1000] Hz, got {args.rates!r}")
    if not (args.rest_s >= 0 and math.isfinite(args.rest_s)):
        parser.error(f"--rest-s must be a finite number >= 0, got {args.rest_s:g}")
    with cli_errors(prog):
        lib = source_library(args.library)
        if args.out:
            return _run(prog, args, rates, lib, Path(args.out))
        out = Path(tempfile.mkdtemp(prefix="foresight-tracker-live-"))
        try:
            status = _run(prog, args, rates, lib, out)
        except BaseException:
            print(f"{prog}: the processes' logs are kept in {out}", file=sys.stderr)
            raise
        shutil.rmtree(out, ignore_errors=True)
        return status


def _run(prog: str, args: argparse.Namespace, rates: list[float], lib: MotionLibrary, out: Path) -> int:
    """The benchmark of :func:`main`'s checked options, the processes' logs in ``out``."""
    model = HumanModel()
    demo = lib.demos[min(max(0, args.demo), len(lib.demos) - 1)]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    plain = ["--no-multicast-scouting"]
    router = ServiceProcess("router", "tools.router", ["--listen", endpoint, *plain], out / "router.log").start()
    tracker = ServiceProcess("tracker", "services.tracker", ["--connect", endpoint, "--listen", "tcp/127.0.0.1:0",
                                                             *plain], out / "tracker.log")
    logs = f"logs in {out}" if args.out else "logs removed at the end (--out keeps them)"
    print(f"{prog}: {demo.class_name} #{demo.index} of {lib.source}, {args.rest_s:g} s of rest around it; {logs}")
    try:
        time.sleep(1.0)  # the router listens
        tracker.start()
        rows = _measure(endpoint, rates, demo.features, args.rest_s, model)
    finally:
        tracker.stop()
        router.stop()
    against = f"vs {rates[0]:g} Hz"
    print(f"{'rate Hz':>8}{'frames':>8}{'poses':>7}{'median ms':>11}{'max ms':>9}{against:>10}")
    base = rows[0][3] if rows and rows[0][3] > 0 else float("nan")
    for rate, sent, poses, med, worst in rows:
        print(f"{rate:>8g}{sent:>8d}{poses:>7d}{med:>11.1f}{worst:>9.1f}{med / base:>9.1f}x")
    return 0


def _measure(endpoint: str, rates: list[float], feats: np.ndarray, rest_s: float,
             model: HumanModel) -> list[tuple[float, int, int, float, float]]:
    """``(rate, frames sent, poses received, median delay ms, max delay ms)`` per rate."""
    keys, lock = Keys(), threading.Lock()
    got: list[tuple[str, int, float]] = []  # ("pose" / "start" / "end" / "lost", demo_id, delay s)
    rest: set[int] = set()  # the demonstrations of the person at rest (services.tracker.demos): not the reach's

    def take(msg: HumanPose | DemoMarker) -> None:
        with lock:
            if isinstance(msg, DemoMarker) and msg.class_name == AT_REST:
                rest.add(msg.demo_id)
            got.append(("pose" if isinstance(msg, HumanPose) else msg.event, msg.demo_id, time.time() - msg.stamp))

    cfg = ZenohConfig(mode="peer", connect=[endpoint], listen=[], multicast_scouting=False)
    rows, frame_no, stop = [], 0, threading.Event()
    with open_session(cfg, stop, "tracker-live bench") as session:
        subscribe(session, keys.pose, HumanPose, take)
        subscribe(session, keys.demo, DemoMarker, take)
        pub: TypedPublisher[HumanKeypoints] = TypedPublisher(session, keys.keypoints, block=True)
        deadline = time.monotonic() + 120.0  # the tracker is up once its subscription to keypoints reaches here
        while not pub.matched():
            if time.monotonic() > deadline:
                raise RuntimeError("the tracker did not subscribe to the keypoints within 120 s")
            time.sleep(0.05)
        for rate in rates:
            with lock:
                got.clear()
            frames = _frames(feats, rate, rest_s, model)
            t0 = time.monotonic()
            for i, p in enumerate(frames):
                time.sleep(max(0.0, t0 + i / rate - time.monotonic()))
                pub.put(HumanKeypoints(stamp=time.time(), tick=-1, frame=frame_no, frame_id="recorder",
                                       names=list(POINT_NAMES), positions=p))
                frame_no += 1
            end = time.monotonic() + 15.0
            while time.monotonic() < end and not any(e == "end" and i not in rest for e, i, _ in list(got)):
                time.sleep(0.05)
            with lock:
                delays = np.array([d for e, i, d in got if e == "pose" and i not in rest]) * 1e3
            rows.append((rate, len(frames), len(delays), float(np.median(delays)) if len(delays) else float("nan"),
                         float(delays.max()) if len(delays) else float("nan")))
            time.sleep(1.0)  # the tracker's silence ends the track: the next rate starts afresh
    return rows


if __name__ == "__main__":
    sys.exit(main())
