"""``foresight train``: fit the class mixtures, regress each class's motion, compute its swept volume.

Per class m (paper IV.B, IV.D): a Gaussian mixture over ``[time, features]`` of all its
demonstrations; the GMR-regressed motion (conditioned on time, :func:`services.predictor.gmr.gmr`);
its occupancy volume ``p(x|C_m)`` in the scene (``--volume``, :mod:`services.predictor.volumes`:
the paper's swept mean motion, the motion with its spread, the demonstrations swept, or those by
time). The posterior temperature tau is chosen by cross-validation on the library
(:mod:`services.predictor.calibration`) unless given, and the novelty threshold learnt on held-out demonstrations
(:mod:`services.predictor.novelty`), scored as recorded or, with ``--sensor-noise-m``, as the tracker gives them.
Everything goes into one model file (:class:`services.predictor.model.PredictionModel`).

The mixtures and motions work on any feature set the library declares; the swept volumes need a
mapping of the features to the human model (``shared.feature_sets``). Without one the model is
written without volumes: it recognises (posteriors) but the predictor service refuses it.
"""

from __future__ import annotations

import argparse
import datetime
import logging
import sys
from collections.abc import MutableMapping
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from shared.arguments import ArgumentParser
from shared.atomic_file import ready_to_write
from shared.feature_sets import LIVE_MAPPING, MappingError, require_mapping
from shared.library import Demonstration, MotionLibrary, heldout_split, load_library
from shared.progress import progress as progress_bar
from shared.runtime import UserError, cli_errors, setup_logging
from shared.scene import SCENE_HELP, Scene, load_scene

from .calibration import DEFAULT_FOLDS, FoldFitError, TemperatureChoice, choose_temperature
from .class_volumes import class_volumes, timed_class_volumes
from .features import VARIANTS, FeatureEncoder
from .fit_cache import cached, class_fit
from .gmm import GMMConfig, GMMError, MixtureBank
from .gmr import gmr
from .model import TIME_FROM, PredictionModel, TimedVolumes, quantised
from .novelty import DEFAULT_QUANTILE, DEFAULT_WINDOW, learn_novelty, through_sensor
from .swept_volume import surface_spacing
from .volumes import DEFAULT_VOLUME, VOLUMES

__all__ = ["TrainConfig", "check_resolution", "train_model", "regress_motions", "default_library", "cached", "main"]

log = logging.getLogger("foresight.train")

DEFAULT_FEATURES = "paper"


@dataclass(frozen=True)
class TrainConfig:
    """Options of ``foresight train``.

    Attributes:
        gmm: Mixture options (components, regularisation, EM, seed).
        features: Feature variant (:data:`services.predictor.features.VARIANTS`).
        time_scale: Time units per sample.
        resolution: Voxel edge (m); ``None``: the scene's ``[grid]`` resolution.
        spacing: Body surface sample spacing (m); never coarser than :func:`~.swept_volume.surface_spacing`.
        interior: Also sample the inside of the body.
        oversample: Regressed postures per library sample used for the swept volumes.
        temperature: Posterior temperature tau stored in the model (1: the paper's posterior);
            ``None``: chosen by ``folds``-fold cross-validation on the training demonstrations.
        volume: How the per-class occupancy is built (:data:`services.predictor.volumes.VOLUMES`).
        folds: Folds of the temperature's cross-validation.
        time_bin: Samples per time bin of the ``timed`` volumes.
        novelty_quantile: The novelty threshold's quantile of the held-out demonstrations' least familiarity
            (:mod:`services.predictor.novelty`).
        novelty_window: Frames of the familiarity's median.
        sensor_noise_m: The novelty threshold's held-out demonstrations are scored as body keypoints with this
            noise per axis (m, seeded by ``gmm.seed``), fitted back as the tracker does
            (:func:`~services.predictor.novelty.through_sensor`); 0: as recorded.
        time_from: ``recording``: a demonstration's sample 0 is its first; ``tracker``: each is cut where the
            tracker's reach rule would start it, and indexed from there, as a live person's reach is.
    """

    gmm: GMMConfig = GMMConfig()
    features: str = DEFAULT_FEATURES
    time_scale: float = 1.0
    resolution: float | None = None
    spacing: float = 0.02
    interior: bool = False
    oversample: int = 4
    temperature: float | None = None
    volume: str = DEFAULT_VOLUME
    folds: int = DEFAULT_FOLDS
    time_bin: int = 5
    novelty_quantile: float = DEFAULT_QUANTILE
    novelty_window: int = DEFAULT_WINDOW
    sensor_noise_m: float = 0.0
    time_from: str = "recording"

    def __repr__(self) -> str:
        """The dataclass's repr, with ``sensor_noise_m`` and ``time_from`` only where not their defaults.

        The demo's and the experiments' model caches key on it: a model trained as before keeps its key (and file).
        """
        shown = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
                          if f.name not in ("sensor_noise_m", "time_from") or getattr(self, f.name) != f.default)
        return f"{type(self).__name__}({shown})"


def default_library(scene: Scene | None = None) -> MotionLibrary:
    """The embedded default library: the synthetic one (``shared.synthetic.generate_library``, seed 0).

    Args:
        scene: The scene whose cups the library's cup classes reach for (default: the default scene).
    """
    from shared.synthetic import generate_library

    return generate_library(seed=0, scene=scene)


def class_data(demos: list[Demonstration], encoder: FeatureEncoder) -> np.ndarray:
    """``(sum T, D)`` stacked feature vectors of ``demos``."""
    return np.vstack([encoder.batch(d.features) for d in demos])


def regress_motions(bank: MixtureBank, lengths: list[int], encoder: FeatureEncoder, oversample: int = 1
                    ) -> list[np.ndarray]:
    """GMR-regressed posture sequence of every class.

    Args:
        bank: Class mixtures.
        lengths: Number of samples T_m of each class's motion.
        encoder: The feature encoder (time scale, posture columns).
        oversample: Postures per sample (1: one per sample index).

    Returns:
        M arrays ``((T_m - 1) * oversample + 1, F)``.
    """
    cols = encoder.posture_columns()
    out = []
    for m, n in enumerate(lengths):
        t = np.arange((n - 1) * oversample + 1) / oversample * encoder.time_scale
        y = gmr(bank.weights_[m], bank.means_[m], bank.covariances_[m], t)
        out.append(np.asarray(y)[:, cols.start - 1: cols.stop - 1])
    return out


def check_resolution(resolution: float | None) -> None:
    """Raise a UserError for a voxel edge outside 0.005..0.5 m (None: the scene's).

    ``eval occupancy`` sweeps the demonstrations before any training: -1 and 0.001 were a traceback and a 43 GiB
    allocation there.
    """
    if resolution is not None and not (0.005 <= resolution <= 0.5):
        raise UserError(f"--resolution must be between 0.005 and 0.5 m, got {resolution}")


def train_model(library: MotionLibrary, scene: Scene, config: TrainConfig | None = None,
                demos: list[Demonstration] | None = None, progress: bool = True,
                fit_cache: MutableMapping[str, Any] | None = None) -> PredictionModel:
    """Train a prediction model.

    Args:
        library: Motion library (classes and demonstrations).
        scene: Scene the volumes are placed in (its ``[grid]`` unless ``config.resolution``).
        config: Options.
        demos: Demonstrations to train on (default: all of ``library``).
        progress: Show tqdm bars.
        fit_cache: Fitted class mixtures (and swept volumes) by a digest of their data and options. Pass
            the same mapping to several calls (e.g. one model per held-out demonstration) and only the
            classes whose data changed are refitted; the fits are seeded, so the model is the same as
            without the cache. A mapping with ``compute`` (:func:`cached`) can be shared between processes.

    Returns:
        The trained model (``volumes`` None when the library's features have no mapping to the human model).
    """
    cfg = config or TrainConfig()
    cfg.gmm.validate()
    if cfg.temperature is not None and not (cfg.temperature > 0 and np.isfinite(cfg.temperature)):
        raise UserError(f"--temperature must be a finite number > 0 or 'auto', got {cfg.temperature}")
    if cfg.features not in VARIANTS:
        raise UserError(f"--features {cfg.features!r} is not one of {', '.join(VARIANTS)}")
    if cfg.volume not in VOLUMES:
        raise UserError(f"--volume {cfg.volume!r} is not one of {', '.join(VOLUMES)}")
    if cfg.folds < 2:
        raise UserError(f"--folds must be >= 2, got {cfg.folds}")
    if not (0.0 <= cfg.novelty_quantile < 1.0):
        raise UserError(f"--novelty-quantile must be in [0, 1), got {cfg.novelty_quantile}")
    if not (1 <= cfg.novelty_window <= 10_000):
        raise UserError(f"novelty window must be in [1, 10000] frames, got {cfg.novelty_window}")
    if not (np.isfinite(cfg.sensor_noise_m) and 0.0 <= cfg.sensor_noise_m < 1.0):
        raise UserError(f"--sensor-noise-m must be in [0, 1) m, got {cfg.sensor_noise_m}")
    if cfg.time_from not in TIME_FROM:
        raise UserError(f"--time-from {cfg.time_from!r} is not one of {', '.join(TIME_FROM)}")
    # the tracker publishes the paper's 12 features: the library's must be them to be fitted back, or to place a wrist
    for what in [w for w, asked in (("--sensor-noise-m (the tracker's fit of body keypoints)", cfg.sensor_noise_m),
                                    ("--time-from tracker (the tracker's reach rule)", cfg.time_from == "tracker"))
                 if asked]:
        try:
            require_mapping(library.feature_names, what, f"library {library.source}", exact=LIVE_MAPPING)
        except MappingError as exc:
            raise UserError(str(exc)) from None
    demos = list(library.demos) if demos is None else demos
    if cfg.time_from == "tracker":  # the tracker's first pose of a reach is its index 0 (docs/keypoints.md)
        from services.tracker.reach import from_tracker_start
        demos = from_tracker_start(demos)
    encoder = FeatureEncoder(cfg.features, cfg.time_scale, feature_names=library.feature_names,
                             source=f"library {library.source}")
    check_resolution(cfg.resolution)
    if not (cfg.spacing > 0 and np.isfinite(cfg.spacing)):
        raise UserError(f"surface sample spacing must be a finite number > 0 m, got {cfg.spacing}")
    grid = scene.grid if cfg.resolution is None else scene.grid.with_resolution(cfg.resolution)
    cfg = replace(cfg, spacing=surface_spacing(cfg.spacing, grid.resolution))
    by_class = [[d for d in demos if d.label == m] for m in range(library.n_classes)]
    empty = [library.class_names[m] for m, ds in enumerate(by_class) if not ds]
    if empty:
        raise UserError(f"library {library.source}: no demonstrations for class(es) {', '.join(empty)}")
    cache: MutableMapping[str, Any] = {} if fit_cache is None else fit_cache

    def fit(data: np.ndarray) -> Any:
        return class_fit(data, cfg.gmm, cache)

    feats = [[encoder.batch(d.features) for d in ds] for ds in by_class]

    def fit_class(m: int) -> Any:
        try:
            return fit(np.vstack(feats[m]))
        except GMMError as exc:  # "cannot fit 150 Gaussians to 100 samples": of which class, it did not say
            raise GMMError(f"class {library.class_names[m]} ({len(feats[m])} demonstration(s)): {exc}") from None

    mixtures = [fit_class(m) for m in progress_bar(range(len(feats)), desc="GMM per class", unit="class",
                                                   enabled=progress)]
    try:
        if cfg.temperature is None:
            with threadpool_limits(1):  # many small fits: one BLAS thread each is several times faster
                choice = choose_temperature(feats, fit, folds=cfg.folds)
        else:
            choice = TemperatureChoice(float(cfg.temperature), "given")
        scored = None if not cfg.sensor_noise_m else [[encoder.batch(f) for f in ds] for ds in through_sensor(
            [[d.features for d in ds] for ds in by_class], cfg.sensor_noise_m, cfg.gmm.seed)]
        with threadpool_limits(1):  # the same folds: their fits are in the cache when the temperature was chosen
            novelty = learn_novelty(feats, fit, cfg.folds, cfg.novelty_window, cfg.novelty_quantile, scored,
                                    cfg.sensor_noise_m)
    except FoldFitError as exc:  # the whole class fitted; a fold without one of its demonstrations did not
        raise UserError(f"library {library.source}: {exc.naming(library.class_names[exc.class_index])}") from None
    bank = MixtureBank.from_sklearn(mixtures)
    lengths = [int(np.median([d.n_samples for d in ds])) for ds in by_class]
    motions = regress_motions(bank, lengths, encoder)
    mapping = library.mapping
    volumes = timed = None
    if mapping is not None and cfg.volume == "timed":
        timed = timed_class_volumes(mapping, scene, grid, cfg, by_class, cache, progress)
        timed = TimedVolumes(timed.support, quantised(timed.values), timed.time_bin)  # as its file holds it
        volumes = np.zeros((library.n_classes, int(np.prod(grid.dims))), np.float32)
        volumes[:, timed.support] = timed.values[:, 0]
        volumes = volumes.reshape(library.n_classes, *grid.dims)
    elif mapping is not None:
        volumes = class_volumes(bank, lengths, encoder, mapping, scene, grid, cfg, by_class, cache, progress)
        if cfg.volume != "paper":
            volumes = quantised(volumes)  # probabilities as its file holds them: a model equals its saved copy
    t_max = max(lengths)
    padded = np.zeros((library.n_classes, t_max, library.n_features))
    for m, mot in enumerate(motions):
        padded[m, : len(mot)] = mot
        padded[m, len(mot):] = mot[-1]
    meta = {"library": library.source, "demos_per_class": [len(ds) for ds in by_class],
            "components": [int(g.n_components) for g in mixtures], "gmm": asdict(cfg.gmm),
            "oversample": cfg.oversample, "temperature": choice.temperature, "temperature_choice": choice.method,
            "temperature_log_loss": {f"{t:g}": v for t, v in choice.mean_log_loss.items()},
            "novelty": novelty.describe() if novelty is not None else "none: a class has fewer than 2 demonstrations",
            "volume": cfg.volume, "last_index": max(d.n_samples for d in demos) - 1,
            "trained_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    return PredictionModel(class_names=list(library.class_names), feature_variant=cfg.features,
                           time_scale=cfg.time_scale, velocity_scale=encoder.velocity_scale,
                           weights=bank.weights_, means=bank.means_, covariances=bank.covariances_,
                           motions=padded, motion_lengths=np.array(lengths, dtype=np.int64), grid=grid,
                           volumes=volumes, scene_name=scene.name,
                           human_pelvis=np.array([*scene.human.pelvis_xyz, scene.human.pelvis_yaw]),
                           spacing=cfg.spacing, interior=cfg.interior, meta=meta, temperature=choice.temperature,
                           feature_names=tuple(library.feature_names), volume_method=cfg.volume,
                           timed=timed, novelty=novelty, time_from=cfg.time_from)


def _temperature(text: str) -> float | None:
    if text.strip().lower() == "auto":
        return None
    try:
        tau = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not 'auto' or a number") from None
    if not (tau > 0 and np.isfinite(tau)):
        raise argparse.ArgumentTypeError(f"must be 'auto' or a finite number > 0, got {text!r}")
    return tau


DESCRIPTION = """Train the prediction model: one Gaussian mixture per motion class over [time, features]
(full covariances, k-means initialisation, seeded), the GMR-regressed motion of each class and its swept
volume in the scene's voxel grid, written to one versioned model file (.npz). Any feature set the library
declares works for the mixtures; the swept volumes need a mapping of the features to the human model
(the paper's 12 features have one): without it the model has no volumes and only recognises."""


def main(argv: list[str] | None = None, prog: str = "foresight train") -> int:
    """``foresight train``; returns the exit status."""
    parser = ArgumentParser(prog=prog, description=DESCRIPTION)
    parser.add_argument("--library", metavar="PATH", default=None,
                        help="motion library: a dir of compound_*.csv or a .npz (default: the synthetic library, "
                             "seed 0)")
    parser.add_argument("--out", metavar="MODEL", default="models/model.npz", help="model file to write; missing "
                        "directories are created (default: models/model.npz)")
    parser.add_argument("--scene", metavar="NAME|PATH", default=None, help=f"{SCENE_HELP} (default: pr2_two_cups); "
                        "the synthetic library's cup classes reach for its cups")
    parser.add_argument("--components", type=int, default=20, help="Gaussians per class; 0 = choose by BIC "
                        "(default: 20, as in the paper)")
    parser.add_argument("--resolution", type=float, default=None, help="voxel edge in metres (default: the "
                        "scene's [grid], 0.05; the planner takes grids down to half the scene's)")
    parser.add_argument("--features", choices=VARIANTS, default=DEFAULT_FEATURES,
                        help=f"feature variant (default: {DEFAULT_FEATURES})")
    parser.add_argument("--reg-covar", type=float, default=GMMConfig.reg_covar,
                        help=f"covariance regularisation (default: {GMMConfig.reg_covar})")
    parser.add_argument("--temperature", type=_temperature, default=None, metavar="auto|TAU",
                        help="posterior temperature tau stored in the model: p(C_m|xi) = softmax(ln p(xi|C_m) / "
                             "tau); 1 = the paper's; auto (default) = the tau of 1 ... 1000 with the least "
                             "cross-validated log-loss on the training demonstrations")
    parser.add_argument("--folds", type=int, default=DEFAULT_FOLDS,
                        help=f"folds of the temperature's cross-validation (default: {DEFAULT_FOLDS})")
    parser.add_argument("--novelty-quantile", type=float, default=DEFAULT_QUANTILE, metavar="Q",
                        help="the novelty test's threshold: the Q quantile of the held-out training demonstrations' "
                             "least familiarity, so about Q of known motions are called unfamiliar at some moment "
                             "(given more than 1/Q demonstrations; 0: the least of them; default: "
                             f"{DEFAULT_QUANTILE})")
    parser.add_argument("--sensor-noise-m", type=float, default=0.0, metavar="SIGMA",
                        help="calibrate the novelty threshold for a sensor: its held-out demonstrations are scored "
                             "as body keypoints with SIGMA of Gaussian noise per axis (m, seeded by --seed), fitted "
                             "back and smoothed as the tracker does (the library must have the paper's 12 features); "
                             "default 0: as recorded")
    parser.add_argument("--time-from", choices=TIME_FROM, default="recording",
                        help="a demonstration's sample 0: recording = its first (the replayer's); tracker = where the "
                             "tracker's reach rule would start it, as a live reach's first pose (default: recording)")
    parser.add_argument("--volume", choices=VOLUMES, default=DEFAULT_VOLUME,
                        help="per-class occupancy p(x|C_m): paper = body swept along the mean motion (0/1); "
                             "spread = trajectories drawn within the GMR covariance; demos = the training "
                             "demonstrations themselves (share that hit a voxel); timed = demos counting only "
                             f"what is still to come at the observed sample; default: {DEFAULT_VOLUME}")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the k-means initialisation and of "
                        "--heldout (default: 0)")
    parser.add_argument("--heldout", type=int, default=0, help="leave out N random demonstrations per class "
                        "(chosen like the replayer's --heldout with the same --seed); default 0")
    parser.add_argument("--interior", action="store_true", help="also sample the inside of the body for the "
                        "swept volumes (default: surface points, as the paper)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    setup_logging()
    with cli_errors(prog):
        if args.seed < 0:  # numpy's and sklearn's errors said neither which option nor which command
            raise UserError(f"--seed must be >= 0, got {args.seed}")
        ready_to_write(args.out)  # before the minutes of training: a directory in the way was found only after them
        scene = load_scene(args.scene)
        lib = load_library(args.library) if args.library else default_library(scene)
        demos = heldout_split(lib, args.heldout, args.seed)[0] if args.heldout else list(lib.demos)
        try:
            gcfg = GMMConfig(n_components=args.components, reg_covar=args.reg_covar, seed=args.seed)
            gcfg.validate()
        except ValueError as exc:
            raise UserError(str(exc)) from None
        cfg = TrainConfig(gmm=gcfg, features=args.features, resolution=args.resolution, interior=args.interior,
                          temperature=args.temperature, volume=args.volume, folds=args.folds,
                          novelty_quantile=args.novelty_quantile, sensor_noise_m=args.sensor_noise_m,
                          time_from=args.time_from)
        model = train_model(lib, scene, cfg, demos, progress=not args.quiet)
        model.save(args.out)
        size = Path(args.out).stat().st_size
        if model.volumes is None:
            occupancy = (f"no swept volumes: {lib.n_features} features without a mapping to the human model "
                         "(recognition only; the predictor service needs a mapping)")
        else:
            occ = (model.volumes.reshape(model.n_classes, -1) > 0).sum(1)
            occupancy = (f"grid {model.grid.dims} at {model.grid.resolution:g} m, "
                         f"{model.volume_method} volumes, voxels per class {occ.tolist()}")
        print(f"wrote {args.out} ({size / 1e6:.2f} MB): {model.n_classes} classes, "
              f"{len(demos)} demonstrations from {lib.source}, features {cfg.features}, "
              f"temperature {model.temperature:g} ({model.meta['temperature_choice']}), "
              f"components {model.meta['components']}, {occupancy}; {model.describe_time()}")
        losses = model.meta["temperature_log_loss"]
        if losses:
            print(f"temperature {model.temperature:g}: least mean log-loss of {cfg.folds}-fold cross-validation; "
                  "by tau: " + ", ".join(f"{t}: {v:.3f}" for t, v in losses.items()))
        print(model.novelty.describe() if model.novelty is not None else
              f"no novelty test: {model.meta['novelty']} (every motion will be called familiar)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
