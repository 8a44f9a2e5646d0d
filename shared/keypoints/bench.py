"""``foresight bench keypoints``: how long fitting the human model to a frame of keypoints takes.

Keypoints are the human model's joint positions of a library's demonstrations (optionally with noise). Three
ways, in one process, one thread: a frame at a time warm-started from the previous fit (what a live tracker
does), a frame at a time from the first guess (the baseline: no warm start), and every frame of the
demonstrations at once (a keypoint library's conversion). Prints the time per frame (median, p99), the ratio
against the baseline, and the fitted joints' distance from the true ones. All at once is one call, timed as a
whole: its time per frame is the mean, and it has no spread to print.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from shared.arguments import ArgumentParser
from shared.human import HumanModel
from shared.library import MotionLibrary
from shared.native_threads import limit_blas_threads
from shared.runtime import cli_errors

from .fit import KeypointFit

__all__ = ["main", "add_source_options", "check_source_options", "source_library"]


def _per_frame(fit: KeypointFit, points: np.ndarray, warm: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(times s (T,), features (T, 12))`` fitting ``points (T, J, 3)`` one frame at a time."""
    times, feats, prior = [], [], None
    for frame in points:
        t0 = time.perf_counter()
        res = fit.fit(frame[None], prior=prior if warm else None)
        times.append(time.perf_counter() - t0)
        feats.append(res.features[0])
        prior = res.features
    return np.array(times), np.array(feats)


def add_source_options(parser: argparse.ArgumentParser, demos: int) -> None:
    """The options of a benchmark on a library's demonstrations seen as keypoints: library, count, noise, seed."""
    parser.add_argument("--library", default=None, help="motion library (default: the synthetic one, seed 0)")
    parser.add_argument("--demos", type=int, default=demos, help="demonstrations, the library's first")
    parser.add_argument("--noise-m", type=float, default=0.0, help="Gaussian noise per axis on the keypoints, m")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise")


def check_source_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Exit with one line (``parser.error``) where :func:`add_source_options`' values make no sense."""
    if args.demos < 1:
        parser.error(f"--demos must be at least 1, got {args.demos}")
    if not (args.noise_m >= 0 and math.isfinite(args.noise_m)):
        parser.error(f"--noise-m must be a finite number >= 0, got {args.noise_m:g}")


def source_library(path: str | None) -> MotionLibrary:
    """The library a keypoint benchmark runs on: ``path``, or the synthetic one (seed 0) when None."""
    if path:
        from shared.library import load_library

        return load_library(path, report=False)
    from shared.synthetic import generate_library

    return generate_library(seed=0)


def main(argv: list[str] | None = None, prog: str = "foresight bench keypoints") -> int:
    """Run the benchmark; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_source_options(parser, demos=4)
    args = parser.parse_args(argv)
    check_source_options(parser, args)
    with cli_errors(prog):
        return _run(prog, args)


def _run(prog: str, args: argparse.Namespace) -> int:
    """The benchmark of :func:`main`'s checked options."""
    limit_blas_threads(1)
    lib = source_library(args.library)
    demos = lib.demos[:args.demos]
    model = HumanModel()
    truth = [model.joint_positions(d.features) for d in demos]
    rng = np.random.default_rng(args.seed)
    observed = [p + rng.normal(0.0, args.noise_m, p.shape) if args.noise_m > 0 else p for p in truth]
    fit = KeypointFit()
    _per_frame(fit, observed[0][:5], True)  # warm-up
    rows, errors = {}, {}
    for name, warm in (("one frame, warm start (live)", True), ("one frame, first guess (baseline)", False)):
        times, feats = [], []
        for obs in observed:
            t, f = _per_frame(fit, obs, warm)
            times.append(t)
            feats.append(f)
        rows[name] = np.concatenate(times)
        errors[name] = np.concatenate([np.linalg.norm(model.joint_positions(f) - p, axis=-1).ravel()
                                       for f, p in zip(feats, truth, strict=True)])
    longest = min(len(o) for o in observed)
    batch = np.stack([o[:longest] for o in observed])
    fit.fit_sequences(batch[:, :5])  # warm-up, as the per-frame ways had
    t0 = time.perf_counter()
    res = fit.fit_sequences(batch)
    at_once = (time.perf_counter() - t0) / (batch.shape[0] * batch.shape[1])  # one call: only its mean per frame
    errors["every frame at once (a library)"] = np.linalg.norm(
        model.joint_positions(res.features) - np.stack([p[:longest] for p in truth]), axis=-1).ravel()
    base = np.median(rows["one frame, first guess (baseline)"])
    print(f"{prog}: {len(demos)} demonstrations of {lib.source}, {sum(len(o) for o in observed)} frames, "
          f"noise {args.noise_m * 100:g} cm per axis, one thread")
    print(f"{'':36}{'ms/frame p50':>13}{'p99':>8}{'vs baseline':>13}{'joint err mm p50':>18}{'p99':>8}")
    for name, e in errors.items():
        t = rows.get(name)
        p50, p99 = (np.median(t), f"{np.percentile(t, 99) * 1e3:>8.2f}") if t is not None else (at_once, f"{'-':>8}")
        print(f"{name:36}{p50 * 1e3:>13.2f}{p99}"
              f"{base / p50:>12.1f}x{np.median(e) * 1e3:>18.2f}{np.percentile(e, 99) * 1e3:>8.2f}")
    print("every frame at once is one call, timed as a whole: its ms/frame is the mean, it has no p99")
    return 0


if __name__ == "__main__":
    sys.exit(main())
