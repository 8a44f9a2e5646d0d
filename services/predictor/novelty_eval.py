"""``foresight eval novelty``: does the novelty test call a motion of a class the model never saw unfamiliar?

Leave one class out: for each class c, the mixtures of the other classes are fitted and their novelty test is
learnt as ``foresight train`` learns it (:func:`services.predictor.novelty.learn_novelty`, the same folds,
window and quantile); then every demonstration of c is played to them frame by frame, as the predictor sees a
live motion. A demonstration is *flagged* when its familiarity falls below the threshold at some frame; the
table gives, per left-out class, the share flagged, the median executed fraction at the first flag, and the
known class the posterior picked instead (the argmax of the summed log-likelihoods at the end, which a
posterior reports however unlike the motion is). The known classes' own held-out demonstrations flagged (the
false alarms, about the quantile by construction) are counted from the same folds, and a last line gives both
shares at other quantiles (the trade-off ``foresight train --novelty-quantile`` chooses on). ``--json`` prints
one object; the PNG shows both.

``--sensor-noise-m SIGMA`` puts every demonstration, known and left out, through the same sensor before it is
scored (:func:`services.predictor.novelty.through_sensor`: body keypoints with SIGMA of noise per axis, seeded, fitted
back as the tracker does), the threshold so calibrated as ``foresight train --sensor-noise-m`` calibrates it: what a
noisy sensor leaves the test able to tell apart. The mixtures stay fitted to the features as recorded.
"""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.atomic_file import ready_to_write
from shared.feature_sets import LIVE_MAPPING, require_mapping
from shared.library import MotionLibrary, load_library
from shared.progress import progress as progress_bar
from shared.runtime import UserError, cli_errors

from .calibration import DEFAULT_FOLDS
from .features import FeatureEncoder
from .fit_cache import class_fit
from .gmm import GMMConfig, MixtureBank
from .novelty import (
    DEFAULT_QUANTILE,
    DEFAULT_WINDOW,
    familiarity,
    first_unfamiliar,
    heldout_minima,
    least_familiarity,
    threshold_at,
    through_sensor,
)
from .train import DEFAULT_FEATURES, default_library

__all__ = ["TRADE_OFF", "LeftOut", "NoveltyResult", "run_novelty", "plot_novelty", "main"]


TRADE_OFF = (0.0, 0.01, 0.05, 0.1, 0.2, 0.3)
"""Quantiles of the trade-off table: unknown motions flagged against known ones, at each."""


@dataclass
class LeftOut:
    """One left-out class played to the others' mixtures.

    Attributes:
        name: The class left out.
        traces: Per demonstration of the class, its ``(T,)`` familiarity frame by frame.
        taken_for: Per demonstration, the known class its summed log-likelihood picked at the end.
        known_minima: ``(N,)`` the known classes' held-out demonstrations' least familiarity (the threshold's data).
    """

    name: str
    traces: list[np.ndarray]
    taken_for: list[str]
    known_minima: np.ndarray

    def threshold(self, quantile: float) -> float:
        """The threshold learnt at ``quantile`` (as :func:`~services.predictor.novelty.learn_novelty`)."""
        return threshold_at(self.known_minima, quantile)

    def first_flag(self, quantile: float) -> np.ndarray:
        """``(N,)`` per demonstration, the executed fraction at its first frame below the threshold (NaN: none)."""
        thr = self.threshold(quantile)
        first = [first_unfamiliar(s, thr) for s in self.traces]
        return np.array([np.nan if t is None else (t + 1) / len(s) for t, s in zip(first, self.traces, strict=True)])

    def flagged(self, quantile: float) -> float:
        """Share of the class's demonstrations flagged at some frame."""
        return float(np.isfinite(self.first_flag(quantile)).mean())

    def known_flagged(self, quantile: float) -> int:
        """Known held-out demonstrations flagged (false alarms)."""
        return int((self.known_minima < self.threshold(quantile)).sum())


@dataclass
class NoveltyResult:
    """Leave-one-class-out novelty detection on one library, at the threshold's ``quantile``."""

    library: str
    window: int
    quantile: float
    classes: list[LeftOut] = field(default_factory=list)
    sensor_noise_m: float = 0.0

    def detection(self, quantile: float | None = None) -> float:
        """Share of all left-out demonstrations flagged."""
        q = self.quantile if quantile is None else quantile
        return float(np.isfinite(np.concatenate([c.first_flag(q) for c in self.classes])).mean())

    def false_alarms(self, quantile: float | None = None) -> float:
        """Share of the known classes' held-out demonstrations flagged, over every left-out class's run."""
        q = self.quantile if quantile is None else quantile
        return sum(c.known_flagged(q) for c in self.classes) / max(1, sum(c.known_minima.size for c in self.classes))

    def lines(self) -> list[str]:
        """The table as text, and the trade-off across quantiles."""
        q = self.quantile
        sensor = (f"; every demonstration as body keypoints with {self.sensor_noise_m * 100:g} cm of noise per axis, "
                  "fitted back as the tracker does" if self.sensor_noise_m else "")
        out = [f"novelty, leave one class out: {self.library} (window {self.window} frames, threshold at the "
               f"{q:g} quantile of the known classes' held-out demonstrations' least familiarity{sensor})",
               f"{'left-out class':<24} {'demos':>5} {'threshold':>10} {'flagged':>8} {'first flag':>11}  "
               "taken for (most often)"]
        for c in self.classes:
            name, count = Counter(c.taken_for).most_common(1)[0]
            first = c.first_flag(q)
            med = float(np.median(first[np.isfinite(first)])) if np.isfinite(first).any() else float("nan")
            out.append(f"{c.name:<24} {len(c.traces):>5} {c.threshold(q):>10.1f} {c.flagged(q):>8.0%} "
                       f"{'-' if np.isnan(med) else f'{med:.0%}':>11}  {name} ({count} of {len(c.taken_for)})")
        out.append(f"unknown motions flagged: {self.detection():.0%}; known motions flagged (false alarms): "
                   f"{self.false_alarms():.1%}")
        out.append("trade-off (quantile: unknown flagged / known flagged): " + ", ".join(
            f"{t:g}: {self.detection(t):.0%} / {self.false_alarms(t):.0%}" for t in TRADE_OFF))
        return out

    def to_json(self) -> dict[str, Any]:
        """One JSON object: the options, per left-out class its numbers, the totals and the trade-off."""
        q = self.quantile
        return {"library": self.library, "window": self.window, "quantile": q, "sensor_noise_m": self.sensor_noise_m,
                "detection": self.detection(), "false_alarms": self.false_alarms(),
                "trade_off": [{"quantile": t, "detection": self.detection(t), "false_alarms": self.false_alarms(t)}
                              for t in TRADE_OFF],
                "classes": [{"name": c.name, "threshold": c.threshold(q), "demos": len(c.traces),
                             "flagged": c.flagged(q), "first_flag": c.first_flag(q).tolist(),
                             "taken_for": c.taken_for, "known_flagged": c.known_flagged(q),
                             "known_heldout": int(c.known_minima.size),
                             "least_familiarity": [least_familiarity(s) for s in c.traces]}
                            for c in self.classes]}


def run_novelty(library: MotionLibrary, gmm: GMMConfig, folds: int = DEFAULT_FOLDS, window: int = DEFAULT_WINDOW,
                quantile: float = DEFAULT_QUANTILE, progress: bool = True, sensor_noise_m: float = 0.0,
                seed: int = 0) -> NoveltyResult:
    """Leave each class out in turn and play its demonstrations to the other classes' novelty test.

    Args:
        library: Motion library (at least 3 classes, 2 demonstrations each).
        gmm: Mixture options.
        folds: Folds of the threshold's held-out scoring.
        window: Frames of the familiarity.
        quantile: The threshold's quantile.
        progress: Show a tqdm bar.
        sensor_noise_m: Every demonstration is scored as body keypoints with this noise per axis (m), fitted back
            as the tracker does (the library must have the paper's 12 features); 0: as recorded.
        seed: Seed of the sensor's noise.
    """
    if library.n_classes < 3 or min(library.counts()) < 2:
        raise UserError(f"library {library.source}: leaving a class out needs >= 3 classes of >= 2 demonstrations, "
                        f"got {library.counts()}")
    enc = FeatureEncoder(DEFAULT_FEATURES, feature_names=library.feature_names, source=f"library {library.source}")
    feats = [[enc.batch(d.features) for d in library.demos if d.label == m] for m in range(library.n_classes)]
    scored = feats
    if sensor_noise_m:
        require_mapping(library.feature_names, "--sensor-noise-m (the tracker's fit of body keypoints)",
                        f"library {library.source}", exact=LIVE_MAPPING)
        scored = [[enc.batch(f) for f in ds] for ds in through_sensor(
            [[d.features for d in library.demos if d.label == m] for m in range(library.n_classes)], sensor_noise_m,
            seed)]
    cache: dict[str, Any] = {}  # a class's fold fits are the same whichever other class is left out
    fit = partial(class_fit, gmm=gmm, cache=cache)
    result = NoveltyResult(library.source, window, quantile, sensor_noise_m=sensor_noise_m)
    names = list(library.class_names)
    for c in progress_bar(range(library.n_classes), desc="novelty (class left out)", unit="class", enabled=progress):
        known = [m for m in range(library.n_classes) if m != c]
        with threadpool_limits(1):
            minima = heldout_minima([feats[m] for m in known], fit, folds, window, [scored[m] for m in known])
            bank = MixtureBank.from_sklearn([fit(np.vstack(feats[m])) for m in known])
        traces, taken = [], []
        for x in scored[c]:
            ll = bank.log_likelihood(x)                                   # (T, M - 1)
            traces.append(familiarity(ll, window))
            taken.append(names[known[int(np.argmax(ll.sum(axis=0)))]])
        result.classes.append(LeftOut(names[c], traces, taken, minima))
    return result


def plot_novelty(result: NoveltyResult, path: str | Path) -> Path:
    """Per left-out class: the share flagged, and when (the first flag's executed fraction), beside the false alarms."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.2), dpi=110)
    x = np.arange(len(result.classes))
    q = result.quantile
    ax1.bar(x, [c.flagged(q) * 100 for c in result.classes], color="tab:red", label="left-out class's demos flagged")
    ax1.axhline(result.false_alarms() * 100, color="k", ls="--", label="known classes' held-out demos flagged")
    ax1.set_xticks(x, [c.name for c in result.classes], rotation=30, ha="right", fontsize=8)
    ax1.set_ylabel("flagged unfamiliar (%)")
    ax1.set_ylim(0, 125)  # the legend above the bars
    ax1.legend(fontsize=8, loc="upper left")
    for i, c in enumerate(result.classes):
        first = c.first_flag(q)
        hit = first[np.isfinite(first)]
        ax2.scatter(np.full(hit.size, i), hit * 100, s=10, color="tab:red", alpha=0.6)
    ax2.set_xticks(x, [c.name for c in result.classes], rotation=30, ha="right", fontsize=8)
    ax2.set_ylabel("executed fraction at the first flag (%)")
    ax2.set_ylim(0, 101)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    sensor = f", keypoints with {result.sensor_noise_m * 100:g} cm noise" if result.sensor_noise_m else ""
    fig.suptitle(f"novelty test, each class left out in turn: {Path(result.library.split(' ')[0]).name} "
                 f"(window {result.window} frames, quantile {result.quantile:g}{sensor})", fontsize=9)
    fig.tight_layout()
    fig.savefig(p)
    plt.close(fig)
    return p


def main(argv: list[str] | None = None, prog: str = "foresight eval") -> int:
    """``foresight eval novelty``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "novelty":
        argv = argv[1:]
    parser = ArgumentParser(prog=f"{prog} novelty", description=__doc__.split("\n\n")[0])
    parser.add_argument("--library", default="synthetic", help="motion library: 'synthetic' or a path (a dir of "
                        "compound_*.csv or an .npz); default: synthetic")
    parser.add_argument("--components", type=int, default=20, help="Gaussians per class (default: 20)")
    parser.add_argument("--folds", type=int, default=DEFAULT_FOLDS, help=f"folds (default: {DEFAULT_FOLDS})")
    parser.add_argument("--window", type=int, default=DEFAULT_WINDOW,
                        help=f"frames of the familiarity's median (default: {DEFAULT_WINDOW})")
    parser.add_argument("--quantile", type=float, default=DEFAULT_QUANTILE,
                        help=f"the threshold's quantile (foresight train --novelty-quantile; default: "
                             f"{DEFAULT_QUANTILE})")
    parser.add_argument("--sensor-noise-m", type=float, default=0.0, metavar="SIGMA",
                        help="score every demonstration as body keypoints with SIGMA of Gaussian noise per axis (m, "
                             "seed 0), fitted back as the tracker does, the threshold calibrated so (foresight train "
                             "--sensor-noise-m); default 0: as recorded")
    parser.add_argument("--plot", type=Path, default=Path("runs/plots/novelty.png"), help="the PNG")
    parser.add_argument("--json", action="store_true", help="print one JSON object (progress goes to stderr)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    with cli_errors(f"{prog} novelty"):
        if args.folds < 2 or args.components < 1 or not 1 <= args.window <= 10_000 or not 0 <= args.quantile < 1 \
                or not 0 <= args.sensor_noise_m < 1:
            raise UserError("--folds must be >= 2, --components >= 1, --window in [1, 10000], --quantile in [0, 1), "
                            "--sensor-noise-m in [0, 1) m")
        ready_to_write(args.plot)
        lib = default_library() if args.library == "synthetic" else load_library(args.library)
        gmm = GMMConfig(n_components=args.components)
        try:
            gmm.validate()
        except ValueError as exc:
            raise UserError(str(exc)) from None
        res = run_novelty(lib, gmm, args.folds, args.window, args.quantile, progress=not args.quiet,
                          sensor_noise_m=args.sensor_noise_m)
        png = plot_novelty(res, args.plot)
        if args.json:
            print(strict_json.dumps({**res.to_json(), "plot": str(png)}))
        else:
            print("\n".join([*res.lines(), f"plot: {png}"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
