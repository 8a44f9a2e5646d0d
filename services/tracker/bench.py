"""``foresight bench tracker``: the tracker's core on a library's demonstrations, as a sensor would give them.

Each demonstration becomes keypoint frames (the human model's joint positions of its features, with ``--rest-s`` of
stillness before and after: a person stands before reaching), sampled at ``--rate-hz`` as a sensor at that rate
would see the person move at the recorded speed (the library's 30 Hz samples interpolated), optionally with Gaussian
noise per axis, and goes through :class:`~services.tracker.core.TrackerCore` frame by frame (one thread). Prints per
demonstration the reaches found, the first pose's lag after the motion's onset and the poses published (both in
the library's samples, at 30 a second whatever the sensor's rate: docs/keypoints.md), the features' median error
against the recording at each pose's time, the frames refused; then the time per fitted frame (median, p99) against the
time between the frames fitted (a sensor faster than ``max_fit_hz`` has its other frames skipped). The baseline, in
the same process, frame by frame interleaved: a second core given the same frames whose fit starts every frame from
the first guess (no warm start from the last frame, :meth:`KeypointFit.fit <shared.keypoints.fit.KeypointFit.fit>`
without a prior); its time per fitted frame and the ratio of its median to the core's are printed last.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from shared.arguments import ArgumentParser
from shared.human import HumanModel
from shared.keypoints.bench import add_source_options, check_source_options, source_library
from shared.keypoints.fit import POINT_NAMES, FitResult, KeypointFit
from shared.native_threads import limit_blas_threads
from shared.runtime import cli_errors

from .core import LIBRARY_RATE_HZ, TrackerConfig, TrackerCore
from .demos import reach_poses

__all__ = ["main", "sample_at"]


def main(argv: list[str] | None = None, prog: str = "foresight bench tracker") -> int:
    """Run the benchmark; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_source_options(parser, demos=6)
    parser.add_argument("--rate-hz", type=float, default=30.0, help="the sensor's frame rate")
    parser.add_argument("--rest-s", type=float, default=1.0, help="stillness before and after each demonstration")
    parser.add_argument("--no-baseline", dest="baseline", action="store_false",
                        help="no baseline core (each fit from the first guess): the table and the time per frame only")
    args = parser.parse_args(argv)
    check_source_options(parser, args)
    if not (args.rate_hz > 0 and math.isfinite(args.rate_hz)):
        parser.error(f"--rate-hz must be a finite number > 0, got {args.rate_hz:g}")
    if not (args.rest_s >= 0 and math.isfinite(args.rest_s)):
        parser.error(f"--rest-s must be a finite number >= 0, got {args.rest_s:g}")
    with cli_errors(prog):
        return _run(prog, args)


class _ColdFit(KeypointFit):
    """The baseline's fit: every frame from the first guess, whatever the core passes as its prior."""

    def fit(self, points: np.ndarray, observed: np.ndarray | None = None, prior: np.ndarray | None = None
            ) -> FitResult:
        """:meth:`KeypointFit.fit` without ``prior``."""
        return super().fit(points, observed, None)


def _timed(core: TrackerCore, stamp: float, points: np.ndarray, times: list[float]) -> list:
    """``core``'s messages for one frame; its time appended to ``times`` when it was fitted (not skipped)."""
    t0, skipped = time.perf_counter(), core.skipped
    out = core.on_frame(stamp, list(POINT_NAMES), points)
    if core.skipped == skipped:  # a frame skipped over max_fit_hz costs nothing: not timed
        times.append(time.perf_counter() - t0)
    return out.messages


def _run(prog: str, args: argparse.Namespace) -> int:
    """The benchmark of :func:`main`'s checked options."""
    limit_blas_threads(1)
    lib = source_library(args.library)
    model, rng = HumanModel(), np.random.default_rng(args.seed)
    rest, times, cold_times, frames = int(round(args.rest_s * LIBRARY_RATE_HZ)), [], [], 0
    print(f"{prog}: {lib.source}, {args.rate_hz:g} Hz, {args.rest_s:g} s of rest around each, noise "
          f"{args.noise_m * 100:g} cm per axis")
    print(f"{'demo':<22}{'reaches':>8}{'lag':>5}{'poses':>7}{'samples':>8}{'pelvis mm':>10}{'angles rad':>11}  refused")
    for d in lib.demos[:args.demos]:
        feats = np.concatenate([np.repeat(d.features[:1], rest, 0), d.features, np.repeat(d.features[-1:], rest, 0)])
        recorded = np.arange(len(feats)) / LIBRARY_RATE_HZ
        stamps = np.arange(0.0, recorded[-1] + 1e-9, 1.0 / args.rate_hz)
        points = model.joint_positions(sample_at(stamps, recorded, feats))
        if args.noise_m > 0:
            points = points + rng.normal(0.0, args.noise_m, points.shape)
        core, cold, poses, at_rest = TrackerCore(model=model), TrackerCore(model=model), [], set()
        cold.fit = _ColdFit(model=model)
        for i, p in enumerate(points):
            if args.baseline and i % 2:  # neither always goes first: machine load falls on both alike
                _timed(cold, float(stamps[i]), p, cold_times)
            poses += reach_poses(_timed(core, float(stamps[i]), p, times), at_rest)
            if args.baseline and not i % 2:
                _timed(cold, float(stamps[i]), p, cold_times)
            frames += 1
        refused = ", ".join(f"{k} {n}" for k, n in core.refused.items() if n) or "-"
        name = f"{d.class_name} #{d.index}"
        if not poses:
            print(f"{name:<22}{core.demos.reaches:>8}{'-':>5}{'-':>7}{len(d.features):>8}{'-':>10}{'-':>11}  {refused}")
            continue
        at = np.array([p.stamp for p in poses])
        err = np.abs(np.array([p.features for p in poses]) - sample_at(at, recorded, feats))
        print(f"{name:<22}{core.demos.reaches:>8}{int(round(at[0] * LIBRARY_RATE_HZ)) - rest:>5}{len(poses):>7}"
              f"{len(d.features):>8}{np.median(err[:, :3]) * 1e3:>10.1f}{np.median(err[:, 3:]):>11.3f}  {refused}")
    ms = np.array(times) * 1e3
    fit_hz = TrackerConfig().max_fit_hz
    print(f"time per frame fitted: median {np.median(ms):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms; {len(ms)} of "
          f"{frames} frames fitted (at most {fit_hz:g} a second: every {1e3 / min(args.rate_hz, fit_hz):.1f} ms; the "
          f"sensor's period {1e3 / args.rate_hz:.1f} ms)")
    if not args.baseline:
        return 0
    cold_ms = np.array(cold_times) * 1e3
    print(f"baseline, each fit from the first guess (no warm start): median {np.median(cold_ms):.2f} ms, p99 "
          f"{np.percentile(cold_ms, 99):.2f} ms; the warm start {np.median(cold_ms) / np.median(ms):.1f}x as fast")
    return 0


def sample_at(t: np.ndarray, recorded: np.ndarray, feats: np.ndarray) -> np.ndarray:
    """The recording ``feats (N, 12)`` at ``recorded (N,)`` s, interpolated at times ``t (M,)``: ``(M, 12)``."""
    return np.stack([np.interp(t, recorded, feats[:, j]) for j in range(feats.shape[1])], axis=-1)


if __name__ == "__main__":
    sys.exit(main())
