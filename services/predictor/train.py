"""``foresight train``: fit the class mixtures, regress each class's motion, compute its swept volume.

Per class m (paper IV.B, IV.D): a Gaussian mixture over ``[time, features]`` of all its
demonstrations; the GMR-regressed motion (conditioned on time, :func:`services.predictor.gmr.gmr`);
the swept volume of that motion placed in the scene. Everything goes into one model file
(:class:`services.predictor.model.PredictionModel`).

The mixtures and motions work on any feature set the library declares; the swept volumes need a
mapping of the features to the human model (``shared.feature_sets``). Without one the model is
written without volumes: it recognises (posteriors) but the predictor service refuses it.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import logging
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from shared.feature_sets import FeatureMapping
from shared.human import HumanModel
from shared.library import Demonstration, MotionLibrary, heldout_split, load_library
from shared.runtime import UserError, cli_errors, setup_logging
from shared.scene import SCENE_HELP, Scene, load_scene

from .features import VARIANTS, FeatureEncoder
from .gmm import DEFAULT_TEMPERATURE, GMMConfig, MixtureBank, fit_class_gmm
from .gmr import gmr
from .model import PredictionModel
from .swept_volume import swept_volume

__all__ = ["TrainConfig", "train_model", "regress_motions", "default_library", "main"]

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
        spacing: Body surface sample spacing (m).
        interior: Also sample the inside of the body.
        oversample: Regressed postures per library sample used for the swept volumes.
        temperature: Posterior temperature tau stored in the model (1: the paper's posterior).
    """

    gmm: GMMConfig = GMMConfig()
    features: str = DEFAULT_FEATURES
    time_scale: float = 1.0
    resolution: float | None = None
    spacing: float = 0.02
    interior: bool = False
    oversample: int = 4
    temperature: float = DEFAULT_TEMPERATURE


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


def train_model(library: MotionLibrary, scene: Scene, config: TrainConfig | None = None,
                demos: list[Demonstration] | None = None, progress: bool = True,
                fit_cache: dict[str, Any] | None = None) -> PredictionModel:
    """Train a prediction model.

    Args:
        library: Motion library (classes and demonstrations).
        scene: Scene the swept volumes are placed in (its ``[grid]`` unless ``config.resolution``).
        config: Options.
        demos: Demonstrations to train on (default: all of ``library``).
        progress: Show tqdm bars.
        fit_cache: Fitted class mixtures by a digest of their training data and mixture options. Pass
            the same dict to several calls (e.g. one model per held-out demonstration) and only the
            classes whose data changed are refitted; the fits are seeded, so the model is the same as
            without the cache.

    Returns:
        The trained model (``volumes`` None when the library's features have no mapping to the human model).
    """
    cfg = config or TrainConfig()
    cfg.gmm.validate()
    if not (cfg.temperature > 0 and np.isfinite(cfg.temperature)):
        raise UserError(f"--temperature must be a finite number > 0, got {cfg.temperature}")
    if cfg.features not in VARIANTS:
        raise UserError(f"--features {cfg.features!r} is not one of {', '.join(VARIANTS)}")
    demos = list(library.demos) if demos is None else demos
    encoder = FeatureEncoder(cfg.features, cfg.time_scale, feature_names=library.feature_names,
                             source=f"library {library.source}")
    grid = scene.grid if cfg.resolution is None else scene.grid.with_resolution(cfg.resolution)
    if cfg.resolution is not None and not (0.005 <= cfg.resolution <= 0.5):
        raise UserError(f"--resolution must be between 0.005 and 0.5 m, got {cfg.resolution}")
    by_class = [[d for d in demos if d.label == m] for m in range(library.n_classes)]
    empty = [library.class_names[m] for m, ds in enumerate(by_class) if not ds]
    if empty:
        raise UserError(f"library {library.source}: no demonstrations for class(es) {', '.join(empty)}")
    mixtures = []
    for m in tqdm(range(library.n_classes), desc="GMM per class", unit="class", disable=not progress):
        data = class_data(by_class[m], encoder)
        key = hashlib.sha256(np.ascontiguousarray(data).tobytes() + repr(cfg.gmm).encode()).hexdigest()
        if fit_cache is not None and key in fit_cache:
            mixture = fit_cache[key]
        else:
            mixture = fit_class_gmm(data, cfg.gmm)
            if fit_cache is not None:
                fit_cache[key] = mixture
        mixtures.append(mixture)
    bank = MixtureBank.from_sklearn(mixtures)
    lengths = [int(np.median([d.n_samples for d in ds])) for ds in by_class]
    motions = regress_motions(bank, lengths, encoder)
    mapping = library.mapping
    volumes = None if mapping is None else _swept_volumes(bank, lengths, encoder, mapping, scene, grid, cfg, progress)
    t_max = max(lengths)
    padded = np.zeros((library.n_classes, t_max, library.n_features))
    for m, mot in enumerate(motions):
        padded[m, : len(mot)] = mot
        padded[m, len(mot):] = mot[-1]
    meta = {"library": library.source, "demos_per_class": [len(ds) for ds in by_class],
            "components": [int(g.n_components) for g in mixtures], "gmm": asdict(cfg.gmm),
            "oversample": cfg.oversample, "temperature": cfg.temperature,
            "trained_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    return PredictionModel(class_names=list(library.class_names), feature_variant=cfg.features,
                           time_scale=cfg.time_scale, velocity_scale=encoder.velocity_scale,
                           weights=bank.weights_, means=bank.means_, covariances=bank.covariances_,
                           motions=padded, motion_lengths=np.array(lengths, dtype=np.int64), grid=grid,
                           volumes=volumes, scene_name=scene.name,
                           human_pelvis=np.array([*scene.human.pelvis_xyz, scene.human.pelvis_yaw]),
                           spacing=cfg.spacing, interior=cfg.interior, meta=meta, temperature=cfg.temperature,
                           feature_names=tuple(library.feature_names))


def _swept_volumes(bank: MixtureBank, lengths: list[int], encoder: FeatureEncoder, mapping: FeatureMapping,
                   scene: Scene, grid, cfg: TrainConfig, progress: bool) -> np.ndarray:
    """``(M, nx, ny, nz)`` bool swept volume of each class's densely regressed motion (human model via ``mapping``)."""
    dense = regress_motions(bank, lengths, encoder, oversample=cfg.oversample)
    human = HumanModel()
    return np.stack([swept_volume(mapping.to_human(mot), scene, grid, human, cfg.spacing, cfg.interior)
                     for mot in tqdm(dense, desc="swept volumes", unit="class", disable=not progress)])


DESCRIPTION = """Train the prediction model: one Gaussian mixture per motion class over [time, features]
(full covariances, k-means initialisation, seeded), the GMR-regressed motion of each class and its swept
volume in the scene's voxel grid, written to one versioned model file (.npz). Any feature set the library
declares works for the mixtures; the swept volumes need a mapping of the features to the human model
(the paper's 12 features have one): without it the model has no volumes and only recognises."""


def main(argv: list[str] | None = None, prog: str = "foresight train") -> int:
    """``foresight train``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    parser.add_argument("--library", metavar="PATH", default=None,
                        help="motion library: a dir of compound_*.csv or a .npz (default: the synthetic library, "
                             "seed 0)")
    parser.add_argument("--out", metavar="MODEL", default="models/model.npz", help="model file to write "
                        "(default: models/model.npz)")
    parser.add_argument("--scene", metavar="NAME|PATH", default=None, help=f"{SCENE_HELP} (default: pr2_two_cups); "
                        "the synthetic library's cup classes reach for its cups")
    parser.add_argument("--components", type=int, default=20, help="Gaussians per class; 0 = choose by BIC "
                        "(default: 20, as in the paper)")
    parser.add_argument("--resolution", type=float, default=None, help="voxel edge in metres (default: the "
                        "scene's [grid], 0.05)")
    parser.add_argument("--features", choices=VARIANTS, default=DEFAULT_FEATURES,
                        help=f"feature variant (default: {DEFAULT_FEATURES})")
    parser.add_argument("--reg-covar", type=float, default=GMMConfig.reg_covar,
                        help=f"covariance regularisation (default: {GMMConfig.reg_covar})")
    parser.add_argument("--temperature", type=float, default=DEFAULT_TEMPERATURE,
                        help="posterior temperature tau stored in the model: p(C_m|xi) = softmax(ln p(xi|C_m) / "
                             f"tau); 1 = the paper's (default: {DEFAULT_TEMPERATURE:g}, chosen by "
                             "`foresight eval recognition`)")
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
        scene = load_scene(args.scene)
        lib = load_library(args.library) if args.library else default_library(scene)
        demos = heldout_split(lib, args.heldout, args.seed)[0] if args.heldout else list(lib.demos)
        try:
            gcfg = GMMConfig(n_components=args.components, reg_covar=args.reg_covar, seed=args.seed)
            gcfg.validate()
        except ValueError as exc:
            raise UserError(str(exc)) from None
        cfg = TrainConfig(gmm=gcfg, features=args.features, resolution=args.resolution, interior=args.interior,
                          temperature=args.temperature)
        model = train_model(lib, scene, cfg, demos, progress=not args.quiet)
        model.save(args.out)
        size = Path(args.out).stat().st_size
        if model.volumes is None:
            occupancy = (f"no swept volumes: {lib.n_features} features without a mapping to the human model "
                         "(recognition only; the predictor service needs a mapping)")
        else:
            occ = model.volumes.reshape(model.n_classes, -1).sum(1)
            occupancy = (f"grid {model.grid.dims} at {model.grid.resolution:g} m, "
                         f"swept voxels per class {occ.tolist()}")
        print(f"wrote {args.out} ({size / 1e6:.2f} MB): {model.n_classes} classes, "
              f"{len(demos)} demonstrations from {lib.source}, features {cfg.features}, "
              f"temperature {cfg.temperature:g}, "
              f"components {model.meta['components']}, {occupancy}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
