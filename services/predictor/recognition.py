"""Early recognition evaluation, the paper's protocol (VI.A): leave one demonstration out.

For each demonstration of class m: refit class m's mixture without it (the other classes keep their
full-data mixtures), then classify its prefixes at executed fractions 10%, 20%, ..., 100% by the
largest ``ln p(xi_1..t | C_j)``. The recognition rate at a fraction is the share of correctly
classified demonstrations. ``foresight eval recognition`` prints the table, writes a PNG of the
curve(s) and, with ``--json``, prints one JSON object.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, MutableMapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from joblib import Parallel, delayed
from sklearn.mixture import GaussianMixture

from shared import strict_json
from shared.arguments import ArgumentParser
from shared.atomic_file import ready_to_write
from shared.feature_sets import describe_features
from shared.library import MotionLibrary, load_library
from shared.progress import progress as progress_bar
from shared.runtime import UserError, cli_errors

from .features import VARIANTS, FeatureEncoder
from .fit_cache import class_fit
from .gmm import DEFAULT_TEMPERATURE, GMMConfig, MixtureBank, posterior_from_log_likelihood
from .model import TIME_FROM
from .train import DEFAULT_FEATURES, default_library

__all__ = ["FRACTIONS", "RecognitionResult", "leave_one_out", "prefix_scores", "plot_recognition", "plot_calibration",
           "main"]

FRACTIONS = tuple(round(0.1 * i, 1) for i in range(1, 11))
PAPER_FIG6 = {"fractions": (0.43, 0.6, 0.8, 1.0), "rates": (0.5, 0.8, 0.92, 0.92)}
"""Reference points read off the paper's Fig. 6 (crosses 50% at 43%, ~80% at 60%, plateau 92% from 80%)."""


@dataclass
class RecognitionResult:
    """Leave-one-out recognition of one feature/mixture variant.

    Attributes:
        name: Label of the variant.
        fractions: Executed fractions.
        rates: Recognition rate at each fraction.
        correct: ``(N, F)`` whether each held-out demonstration's prefix was classified right.
        labels: ``(N,)`` true classes.
        log_likelihood: ``(N, F, M)`` summed ``ln p(xi_1..t | C_m)`` of each prefix (own class refitted
            without the demonstration), from which posteriors at any temperature follow.
    """

    name: str
    fractions: list[float]
    rates: list[float]
    correct: np.ndarray  # (N demos, F) bool
    labels: np.ndarray   # (N,)
    log_likelihood: np.ndarray  # (N, F, M)

    def posteriors(self, temperature: float = 1.0) -> np.ndarray:
        """``(N, F, M)`` class posteriors of every prefix at temperature tau."""
        return posterior_from_log_likelihood(self.log_likelihood, temperature=temperature)

    def log_loss(self, temperature: float = 1.0) -> np.ndarray:
        """``(F,)`` mean negative natural log posterior of the true class (posteriors floored at 1e-12)."""
        p = np.take_along_axis(self.posteriors(temperature), self.labels[:, None, None], axis=2)[..., 0]
        return -np.log(np.maximum(p, 1e-12)).mean(axis=0)

    def brier(self, temperature: float = 1.0) -> np.ndarray:
        """``(F,)`` mean Brier score ``sum_m (p_m - [m = true])^2`` (0 best, 2 worst)."""
        p = self.posteriors(temperature)
        onehot = np.eye(p.shape[-1])[self.labels][:, None, :]
        return ((p - onehot) ** 2).sum(axis=-1).mean(axis=0)

    def best_temperature(self, candidates: tuple[float, ...]) -> float:
        """The candidate tau with the least log-loss averaged over the fractions."""
        return float(min(candidates, key=lambda tau: float(self.log_loss(tau).mean())))

    def per_class(self) -> np.ndarray:
        """``(M, F)`` recognition rate per class."""
        m = int(self.labels.max()) + 1
        return np.stack([self.correct[self.labels == c].mean(axis=0) for c in range(m)])


def _prefix_lengths(n: int, fractions: tuple[float, ...]) -> np.ndarray:
    return np.clip(np.rint(np.asarray(fractions) * n).astype(int), 1, n)


def prefix_scores(i: int, x: np.ndarray, feats: list[np.ndarray], labels: np.ndarray, full: MixtureBank,
                  fit: Callable[[np.ndarray], GaussianMixture], fractions: tuple[float, ...]) -> np.ndarray:
    """``(F, M)`` summed ``ln p(x_1..t | C_m)`` of ``x``'s prefixes at ``fractions``, ``i``'s class refitted without it.

    Args:
        i: The held-out demonstration (its class's mixture is refitted on the others' ``feats``).
        x: ``(T, D)`` the encoded motion to classify: demonstration ``i``'s features, or the tracker's poses of it.
        feats: Every demonstration's ``(T_j, D)`` encoded features.
        labels: ``(N,)`` their classes.
        full: The mixtures fitted on every demonstration.
        fit: Fits one class's mixture.
        fractions: Executed fractions.
    """
    m = int(labels[i])
    own = MixtureBank.from_sklearn([fit(np.vstack([feats[j] for j in np.flatnonzero(labels == m) if j != i]))])
    ll = full.log_likelihood(x)                         # (T, M)
    ll[:, m] = own.log_likelihood(x)[:, 0]
    return np.cumsum(ll, axis=0)[_prefix_lengths(len(ll), fractions) - 1]  # (F, M)


def leave_one_out(library: MotionLibrary, cfg: GMMConfig, features: str = DEFAULT_FEATURES,
                  fractions: tuple[float, ...] = FRACTIONS, n_jobs: int = 2, progress: bool = True,
                  name: str | None = None, fit_cache: MutableMapping[str, Any] | None = None) -> RecognitionResult:
    """Run the leave-one-out protocol.

    Args:
        library: Motion library (at least 2 demonstrations per class; any feature set for ``paper``).
        cfg: Mixture options.
        features: Feature variant.
        fractions: Executed fractions to classify at.
        n_jobs: Parallel refits (joblib processes).
        progress: Show a tqdm bar.
        name: Label of the result (default: ``features`` and components).
        fit_cache: The trainer's fit cache (:func:`~services.predictor.fit_cache.class_fit`): the refits are the
            class fits of the models trained without each demonstration, so the report's recognition and its
            held-out models fit each once between them. Read in this process: ``n_jobs`` must be 1.

    Returns:
        The recognition rates.
    """
    enc = FeatureEncoder(features, feature_names=library.feature_names, source=f"library {library.source}")
    demos = library.demos
    counts = library.counts()
    if min(counts) < 2:
        raise UserError(f"library {library.source}: leave-one-out needs >= 2 demonstrations per class, got {counts}")
    if fit_cache is not None and n_jobs != 1:
        raise ValueError(f"leave_one_out: a fit cache is read in this process, so n_jobs must be 1, got {n_jobs}")
    fit = partial(class_fit, gmm=cfg, cache=fit_cache)
    feats = [enc.batch(d.features) for d in demos]
    labels = np.array([d.label for d in demos])
    full = Parallel(n_jobs=n_jobs)(delayed(fit)(np.vstack([feats[j] for j in np.flatnonzero(labels == m)]))
                                   for m in range(library.n_classes))
    bank = MixtureBank.from_sklearn(full)
    jobs = (delayed(prefix_scores)(i, feats[i], feats, labels, bank, fit, fractions) for i in range(len(demos)))
    it = Parallel(n_jobs=n_jobs, return_as="generator")(jobs)
    cum = np.array(list(progress_bar(it, total=len(demos), desc=f"leave-one-out ({features})", unit="demo",
                                     enabled=progress)))                   # (N, F, M)
    correct = np.argmax(cum, axis=2) == labels[:, None]
    label = name or f"Foresight, {features} features, {cfg.n_components or 'BIC'} Gaussians per class"
    return RecognitionResult(label, list(fractions), correct.mean(axis=0).tolist(), correct, labels, cum)


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


def plot_calibration(result: RecognitionResult, temperatures: tuple[float, ...], path: str | Path,
                     title: str = "", bins: int = 10) -> Path:
    """Calibration of the class posteriors at the given temperatures (one PNG, three panels).

    Left: log-loss of the true class against executed fraction. Middle: recognition rate (the same
    for every tau) and the mean posterior of the top class (its confidence). Right: reliability
    diagram over all fractions: accuracy of the top class against its posterior, in ``bins`` bins
    (a calibrated predictor lies on the diagonal).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    x = np.array(result.fractions) * 100
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.2), dpi=110)
    axes[1].plot(x, np.array(result.rates) * 100, "k-o", label="recognition rate (any tau)")
    edges = np.linspace(0.0, 1.0, bins + 1)
    for tau in temperatures:
        post = result.posteriors(tau)                                   # (N, F, M)
        top = post.max(axis=2)
        loss = result.log_loss(tau)
        axes[0].plot(x, loss, marker="o", label=f"tau = {tau:g} (mean {loss.mean():.2f})")
        axes[1].plot(x, top.mean(axis=0) * 100, marker=".", ls="--", label=f"mean top posterior, tau = {tau:g}")
        which = np.clip(np.digitize(top.ravel(), edges) - 1, 0, bins - 1)
        ok = result.correct.ravel()
        conf = [top.ravel()[which == b].mean() for b in range(bins) if np.any(which == b)]
        acc = [ok[which == b].mean() for b in range(bins) if np.any(which == b)]
        axes[2].plot(conf, acc, marker="o", label=f"tau = {tau:g}")
    axes[0].axhline(np.log(result.log_likelihood.shape[-1]), color="grey", ls=":", label="uniform posterior")
    axes[0].set_ylabel("log-loss: mean -ln p(true class | prefix)")
    axes[1].set_ylabel("%")
    for ax in axes[:2]:
        ax.set_xlabel("executed fraction of the motion (%)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[2].plot([0, 1], [0, 1], "k:", label="calibrated")
    axes[2].set_xlabel("posterior of the top class (binned)")
    axes[2].set_ylabel("share of those top classes that are right")
    axes[2].set_xlim(0, 1)
    axes[2].set_ylim(0, 1)
    axes[2].grid(alpha=0.3)
    axes[2].legend(fontsize=7)
    fig.suptitle(title or f"posterior calibration: {result.name}", fontsize=9)
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


def format_calibration(result: RecognitionResult, temperatures: tuple[float, ...]) -> str:
    """Log-loss and Brier score per executed fraction, one column pair per temperature."""
    head = "executed  " + "  ".join(f"{'log-loss tau=' + format(t, 'g'):>16} {'Brier':>6}" for t in temperatures)
    rows = [head, "-" * len(head)]
    cols = [(r.log_loss(t), r.brier(t)) for t in temperatures for r in [result]]
    for k, f in enumerate(result.fractions):
        rows.append(f"{f * 100:7.0f}%  " + "  ".join(f"{ll[k]:16.3f} {br[k]:6.3f}" for ll, br in cols))
    rows.append("   mean   " + "  ".join(f"{ll.mean():16.3f} {br.mean():6.3f}" for ll, br in cols))
    return "\n".join(rows)


DEFAULT_TEMPERATURE_GRID = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 150.0, 200.0, 300.0, 500.0, 1000.0)

DESCRIPTION = """Evaluate early recognition with the paper's protocol: leave one demonstration out, refit
only its class without it, classify its prefixes at executed fractions 10%..100%. Prints a table of the
recognition rate and of the calibration of the class posteriors (log-loss = mean -ln p(true class), Brier
score) at temperature 1 (the paper) and --temperature, and the temperature of a grid with the least mean
log-loss; writes a PNG of recognition rate against executed fraction and one of the calibration;
--json prints one JSON object instead of the tables. --through-tracker classifies, instead of each held-out
demonstration's recorded features, the poses the tracker publishes for it played as a person's body keypoints
(services/tracker/sensed.py; docs/keypoints.md)."""


def main(argv: list[str] | None = None, prog: str = "foresight eval") -> int:
    """``foresight eval recognition``; returns the exit status."""
    parser = ArgumentParser(prog=prog, description="Evaluate Foresight components.")
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
    p.add_argument("--seed", type=int, default=0, help="k-means seed, and the keypoint noise's (default: 0)")
    p.add_argument("--through-tracker", action="store_true", help="classify the poses the tracker publishes for each "
                   "held-out demonstration played as body keypoints (at rest 1.5 s before and after), at fractions of "
                   "its first reach's poses")
    p.add_argument("--keypoint-noise-m", type=float, default=None, metavar="SIGMA",
                   help="--through-tracker: Gaussian noise of the keypoints per axis, m (default: 0)")
    p.add_argument("--time-from", choices=TIME_FROM, default=None,
                   help="--through-tracker: the mixtures' time from each demonstration's first sample (recording, "
                   "the default) or from where the tracker starts its reach (tracker, as foresight train --time-from)")
    p.add_argument("--n-jobs", type=int, default=2, help="parallel refits (default: 2)")
    p.add_argument("--json", action="store_true", help="print one JSON object {fractions, recognition_rates, ...}")
    p.add_argument("--plot", metavar="PNG", default="runs/plots/recognition.png",
                   help="plot file (default: runs/plots/recognition.png)")
    p.add_argument("--temperature", type=float, default=DEFAULT_TEMPERATURE,
                   help=f"posterior temperature tau to report besides 1 (default: {DEFAULT_TEMPERATURE:g})")
    p.add_argument("--temperatures", metavar="T1,T2,...", default=",".join(f"{t:g}" for t in DEFAULT_TEMPERATURE_GRID),
                   help="grid searched for the least mean log-loss (default: %(default)s)")
    p.add_argument("--calibration-plot", metavar="PNG", default="runs/plots/calibration.png",
                   help="calibration plot file (default: runs/plots/calibration.png)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    with cli_errors(f"{prog} recognition"):
        try:
            grid = tuple(float(t) for t in args.temperatures.split(",") if t.strip())
        except ValueError:
            raise UserError(f"--temperatures: {args.temperatures!r} is not a comma-separated list of numbers") from None
        if not grid or not all(t > 0 and np.isfinite(t) for t in (*grid, args.temperature)):
            raise UserError("--temperature/--temperatures: temperatures must be finite numbers > 0")
        if args.n_jobs == 0:
            raise UserError("--n-jobs: 0 runs nothing; give >= 1, or a negative number for all cores but -n-1")
        for opt, given in (("--keypoint-noise-m", args.keypoint_noise_m), ("--time-from", args.time_from)):
            if given is not None and not args.through_tracker:
                raise UserError(f"{opt}: only with --through-tracker (the recorded features have neither)")
        noise = 0.0 if args.keypoint_noise_m is None else args.keypoint_noise_m
        if not (np.isfinite(noise) and 0.0 <= noise < 1.0):
            raise UserError(f"--keypoint-noise-m must be in [0, 1) m, got {noise:g}")
        for png in (args.plot, args.calibration_plot):  # before the work: a file in the way lost it all
            ready_to_write(png)
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
        results, tracked = [], []
        if args.through_tracker:
            from .recognition_tracker import leave_one_out_tracked, sense_library, tracker_label

            sensed = sense_library(lib, noise, args.seed, args.n_jobs, progress=not args.quiet)
        for feats, k in variants:
            cfg = GMMConfig(n_components=k, reg_covar=args.reg_covar, max_iter=args.max_iter, seed=args.seed)
            try:
                cfg.validate()
            except ValueError as exc:
                raise UserError(str(exc)) from None
            if args.through_tracker:
                tracked.append(leave_one_out_tracked(
                    lib, cfg, sensed, feats, args.time_from or "recording", n_jobs=args.n_jobs,
                    progress=not args.quiet, name=f"Foresight, {feats} features, {k or 'BIC'} Gaussians per class, "
                    f"{tracker_label(noise, args.time_from or 'recording')}"))
                results.append(tracked[-1].result)
            else:
                results.append(leave_one_out(lib, cfg, feats, n_jobs=args.n_jobs, progress=not args.quiet))
        where = f"{Path(lib.source).name} ({len(lib.demos)} demos, {lib.n_classes} classes)"
        png = plot_recognition(results, args.plot, f"leave-one-out recognition: {where}")
        main_res = results[0]
        best = main_res.best_temperature(grid)
        taus = tuple(dict.fromkeys((1.0, args.temperature, best)))
        cal = plot_calibration(main_res, taus, args.calibration_plot, f"posterior calibration, leave-one-out: {where}, "
                               f"{main_res.name}")
        if args.json:
            out = {"fractions": main_res.fractions, "recognition_rates": main_res.rates,
                   "temperature": args.temperature,
                   "log_loss": main_res.log_loss(args.temperature).tolist(),
                   "brier": main_res.brier(args.temperature).tolist(),
                   "log_loss_tau1": main_res.log_loss(1.0).tolist(), "brier_tau1": main_res.brier(1.0).tolist(),
                   "mean_log_loss_by_temperature": {f"{t:g}": float(main_res.log_loss(t).mean()) for t in grid},
                   "best_temperature": best,
                   "variant": main_res.name, "library": lib.source, "n_demos": len(lib.demos),
                   "n_features": lib.n_features,
                   "plot": str(png), "calibration_plot": str(cal)}
            if len(results) > 1:
                out["variants"] = {r.name: r.rates for r in results}
            if tracked:
                out["through_tracker"] = tracked[0].summary(noise, args.time_from or "recording", args.seed)
            print(strict_json.dumps(out))
        else:
            print(f"leave-one-out recognition on {lib.source}: {len(lib.demos)} demonstrations, "
                  f"{lib.n_classes} classes, features {describe_features(lib.feature_names)}")
            if tracked:
                print(tracked[0].line())
            print(format_table(results))
            print(f"\nposterior calibration of {main_res.name} (log-loss: mean -ln p(true class | prefix); "
                  f"uniform = {np.log(lib.n_classes):.3f}):")
            print(format_calibration(main_res, taus))
            print("mean log-loss by temperature: " + ", ".join(f"{t:g}: {main_res.log_loss(t).mean():.3f}"
                                                                for t in grid) + f"  -> least at tau = {best:g}")
            print(f"plot: {png}\ncalibration plot: {cal}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
