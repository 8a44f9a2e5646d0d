"""Early recognition evaluation, the paper's protocol (VI.A): leave one demonstration out.

For each demonstration of class m: refit class m's mixture without it (the other classes keep their
full-data mixtures), then classify its prefixes at executed fractions 10%, 20%, ..., 100% by the
largest ``ln p(xi_1..t | C_j)``. The recognition rate at a fraction is the share of correctly
classified demonstrations. ``foresight eval recognition`` prints the table, writes a PNG of the
curve(s) and, with ``--json``, prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed
from tqdm import tqdm

from shared.library import MotionLibrary, load_library
from shared.runtime import UserError, cli_errors

from .features import VARIANTS, FeatureEncoder
from .gmm import GMMConfig, MixtureBank, fit_class_gmm
from .train import DEFAULT_FEATURES, default_library

__all__ = ["FRACTIONS", "RecognitionResult", "leave_one_out", "plot_recognition", "main"]

FRACTIONS = tuple(round(0.1 * i, 1) for i in range(1, 11))
PAPER_FIG6 = {"fractions": (0.43, 0.6, 0.8, 1.0), "rates": (0.5, 0.8, 0.92, 0.92)}
"""Reference points read off the paper's Fig. 6 (crosses 50% at 43%, ~80% at 60%, plateau 92% from 80%)."""


@dataclass
class RecognitionResult:
    """Leave-one-out recognition of one feature/mixture variant."""

    name: str
    fractions: list[float]
    rates: list[float]
    correct: np.ndarray  # (N demos, F) bool
    labels: np.ndarray   # (N,)

    def per_class(self) -> np.ndarray:
        """``(M, F)`` recognition rate per class."""
        m = int(self.labels.max()) + 1
        return np.stack([self.correct[self.labels == c].mean(axis=0) for c in range(m)])


def _prefix_lengths(n: int, fractions: tuple[float, ...]) -> np.ndarray:
    return np.clip(np.rint(np.asarray(fractions) * n).astype(int), 1, n)


def _score_demo(i: int, feats: list[np.ndarray], labels: np.ndarray, full: MixtureBank, cfg: GMMConfig,
                fractions: tuple[float, ...]) -> np.ndarray:
    m = int(labels[i])
    rest = np.vstack([feats[j] for j in np.flatnonzero(labels == m) if j != i])
    own = MixtureBank.from_sklearn([fit_class_gmm(rest, cfg)])
    ll = full.log_likelihood(feats[i])                  # (T, M)
    ll[:, m] = own.log_likelihood(feats[i])[:, 0]
    cum = np.cumsum(ll, axis=0)
    pred = np.argmax(cum[_prefix_lengths(len(ll), fractions) - 1], axis=1)
    return pred == m


def leave_one_out(library: MotionLibrary, cfg: GMMConfig, features: str = DEFAULT_FEATURES,
                  fractions: tuple[float, ...] = FRACTIONS, n_jobs: int = 2, progress: bool = True,
                  name: str | None = None) -> RecognitionResult:
    """Run the leave-one-out protocol.

    Args:
        library: Motion library (at least 2 demonstrations per class).
        cfg: Mixture options.
        features: Feature variant.
        fractions: Executed fractions to classify at.
        n_jobs: Parallel refits (joblib processes).
        progress: Show a tqdm bar.
        name: Label of the result (default: ``features`` and components).

    Returns:
        The recognition rates.
    """
    enc = FeatureEncoder(features)
    demos = library.demos
    counts = library.counts()
    if min(counts) < 2:
        raise UserError(f"library {library.source}: leave-one-out needs >= 2 demonstrations per class, got {counts}")
    feats = [enc.batch(d.features) for d in demos]
    labels = np.array([d.label for d in demos])
    full = Parallel(n_jobs=n_jobs)(delayed(fit_class_gmm)(np.vstack([feats[j] for j in np.flatnonzero(labels == m)]),
                                                          cfg) for m in range(library.n_classes))
    bank = MixtureBank.from_sklearn(full)
    jobs = (delayed(_score_demo)(i, feats, labels, bank, cfg, fractions) for i in range(len(demos)))
    it = Parallel(n_jobs=n_jobs, return_as="generator")(jobs)
    correct = np.array(list(tqdm(it, total=len(demos), desc=f"leave-one-out ({features})", unit="demo",
                                 disable=not progress)))
    label = name or f"{features}, {cfg.n_components or 'BIC'} Gaussians"
    return RecognitionResult(label, list(fractions), correct.mean(axis=0).tolist(), correct, labels)


def plot_recognition(results: list[RecognitionResult], path: str | Path, title: str = "") -> Path:
    """Recognition rate against executed fraction, one curve per result, plus the paper's Fig. 6 points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    for r in results:
        ax.plot(np.array(r.fractions) * 100, np.array(r.rates) * 100, marker="o", label=r.name)
    ax.plot(np.array(PAPER_FIG6["fractions"]) * 100, np.array(PAPER_FIG6["rates"]) * 100, "k*", ms=10,
            label="paper Fig. 6 (read off)")
    ax.set_xlabel("executed fraction of the motion (%)")
    ax.set_ylabel("recognition rate (%)")
    ax.set_xlim(5, 102)
    ax.set_ylim(0, 101)
    ax.grid(alpha=0.3)
    ax.set_title(title or "leave-one-out recognition", fontsize=9)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(p)
    plt.close(fig)
    return p


def format_table(results: list[RecognitionResult]) -> str:
    """Fractions as rows, one column per result."""
    head = "executed  " + "  ".join(f"{r.name:>24}" for r in results)
    rows = [head, "-" * len(head)]
    for k, f in enumerate(results[0].fractions):
        rows.append(f"{f * 100:7.0f}%  " + "  ".join(f"{r.rates[k] * 100:23.1f}%" for r in results))
    return "\n".join(rows)


DESCRIPTION = """Evaluate early recognition with the paper's protocol: leave one demonstration out, refit
only its class without it, classify its prefixes at executed fractions 10%..100%. Prints a table, writes a
PNG of recognition rate against executed fraction; --json prints one JSON object instead of the table."""


def main(argv: list[str] | None = None, prog: str = "foresight eval") -> int:
    """``foresight eval recognition``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description="Evaluate Foresight components.")
    sub = parser.add_subparsers(dest="what", required=True, metavar="{recognition}")
    p = sub.add_parser("recognition", description=DESCRIPTION, help="leave-one-out early recognition")
    p.add_argument("--library", metavar="PATH", default=None,
                   help="motion library: a dir of compound_*.csv or a .npz (default: the synthetic library, seed 0)")
    p.add_argument("--components", type=int, default=20, help="Gaussians per class, 0 = by BIC (default: 20)")
    p.add_argument("--features", choices=VARIANTS, default=DEFAULT_FEATURES,
                   help=f"feature variant (default: {DEFAULT_FEATURES})")
    p.add_argument("--compare", metavar="VARIANT[:N]", default="",
                   help="also evaluate these variants (comma-separated, e.g. paper:20,relative:0) and plot all")
    p.add_argument("--reg-covar", type=float, default=GMMConfig.reg_covar, help="covariance regularisation")
    p.add_argument("--max-iter", type=int, default=100, help="EM iterations at most (default: 100)")
    p.add_argument("--seed", type=int, default=0, help="k-means seed (default: 0)")
    p.add_argument("--n-jobs", type=int, default=2, help="parallel refits (default: 2)")
    p.add_argument("--json", action="store_true", help="print one JSON object {fractions, recognition_rates, ...}")
    p.add_argument("--plot", metavar="PNG", default="runs/plots/recognition.png",
                   help="plot file (default: runs/plots/recognition.png)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    with cli_errors(f"{prog} recognition"):
        lib = load_library(args.library) if args.library else default_library()
        variants = [(args.features, args.components)]
        for item in filter(None, (s.strip() for s in args.compare.split(","))):
            name, _, n = item.partition(":")
            if name not in VARIANTS:
                raise UserError(f"--compare: {name!r} is not one of {', '.join(VARIANTS)}")
            try:
                variants.append((name, int(n) if n else args.components))
            except ValueError:
                raise UserError(f"--compare: {item!r}: components must be an integer") from None
        results = []
        for feats, k in variants:
            cfg = GMMConfig(n_components=k, reg_covar=args.reg_covar, max_iter=args.max_iter, seed=args.seed)
            try:
                cfg.validate()
            except ValueError as exc:
                raise UserError(str(exc)) from None
            results.append(leave_one_out(lib, cfg, feats, n_jobs=args.n_jobs, progress=not args.quiet))
        png = plot_recognition(results, args.plot, f"leave-one-out recognition: {Path(lib.source).name} "
                               f"({len(lib.demos)} demos, {lib.n_classes} classes)")
        if args.json:
            out = {"fractions": results[0].fractions, "recognition_rates": results[0].rates,
                   "variant": results[0].name, "library": lib.source, "n_demos": len(lib.demos),
                   "plot": str(png)}
            if len(results) > 1:
                out["variants"] = {r.name: r.rates for r in results}
            print(json.dumps(out))
        else:
            print(f"leave-one-out recognition on {lib.source}: {len(lib.demos)} demonstrations, "
                  f"{lib.n_classes} classes")
            print(format_table(results))
            print(f"plot: {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
