"""The predictor's pure core (no Zenoh): early recognition and predicted workspace occupancy.

For the demonstration being observed (paper IV.C, IV.E):

- every new posture ``xi_t`` adds ``ln p(xi_t | C_m)`` to each class's running log-likelihood
  (constant work per pose);
- ``p(C_m | xi) = p(xi | C_m)^(1/tau) / sum_j p(xi | C_j)^(1/tau)`` by log-sum-exp normalisation, with
  the temperature tau of the model file (or ``PredictorConfig.temperature``); tau = 1 is the paper's
  posterior, tau > 1 deflates the over-counted evidence of correlated samples (calibration);
- ``p(x | xi) = sum_m p(x | C_m) p(C_m | xi)``, with ``p(x | C_m)`` the class's volume of the model
  file (the paper's swept mean motion, 0/1, or a volume with the motion's spread, in [0, 1]:
  ``services.predictor.volumes``); the result stays in [0, 1].

Only voxels inside the union of the swept volumes can be non-zero, so the occupancy is one
``(M,) @ (M, U)`` float32 product over those U voxels. The baseline ``current`` method returns
the voxels of the current posture only (placed in the scene relative to the demonstration's
first pelvis pose).

The posterior sums to 1 for a motion unlike every class too, often with one class near 1. So each posture
also updates the motion's familiarity (:mod:`services.predictor.novelty`): how well the best class explains
the last frames, against the model's novelty threshold. An unfamiliar motion is flagged; with
``unfamiliar = "all-classes"`` its occupancy is every known class's volume at once (``max_m p(x | C_m)``)
rather than the posterior's mixture.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shared.config import LOG_LEVELS, ConfigError, opt
from shared.feature_sets import LIVE_MAPPING, herakles_out_of_range, require_mapping
from shared.human import HumanModel, place_in_scene
from shared.protocol import OccupancyGrid
from shared.scene import SCENE_HELP, Grid, Scene

from .gmm import posterior_from_log_likelihood
from .model import PredictionModel
from .novelty import DEFAULT_WINDOW, MIN_FRAMES, FamiliarityWindow
from .swept_volume import posture_voxels

__all__ = ["PredictorConfig", "PredictionResult", "PredictorCore", "PredictorError", "METHODS"]

METHODS = ("prediction", "current")
UNFAMILIAR = ("report", "all-classes")


def _read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a`` (the array itself stays writable where it was)."""
    v = a.view()
    v.setflags(write=False)
    return v


class PredictorError(ValueError):
    """Bad input to the predictor core (wrong shape, NaN); the message names it."""


@dataclass
class PredictorConfig:
    """Options of the predictor service (``[predictor]`` in the TOML config)."""

    model: Path = opt(Path("models/model.npz"), help="prediction model file written by `foresight train`")
    scene: str = opt("", help=SCENE_HELP + " (empty: pr2_two_cups); must be the model's")
    method: str = opt("prediction", help="occupancy published: predicted p(x|xi) or the current posture only",
                      choices=METHODS)
    temperature: float = opt(0.0, help="posterior temperature tau: p(C_m|xi) = softmax(ln p(xi|C_m) / tau); "
                             "1 = the paper's; 0 = the model file's (set by `foresight train --temperature`)")
    evidence: str = opt("sum", help="how the observed frames weigh: 'sum' (ln p(xi|C_m) summed over the frames, the "
                        "paper's text) or 'mean' (divided by the frames observed: the per-frame mean log-likelihood "
                        "whose softmax the authors' code takes, HRICS_ClassifyMotion.cpp)", choices=("sum", "mean"))
    unfamiliar: str = opt("report", help="a motion the model finds unfamiliar (below its novelty threshold): "
                          "'report' (flagged in the ClassPosterior, occupancy from the posterior as ever) or "
                          "'all-classes' (flagged, and the occupancy is every class's volume at once)",
                          choices=UNFAMILIAR)
    grid_interval_s: float = opt(0.02, help="real time: at least this long between two occupancy grids (the "
                                 "newest pose's grid is owed and sent once due; 0: a grid for every pose)")
    backlog: int = opt(3000, help="most messages waiting to be processed (about 10 s at 300 Hz); beyond it the "
                       "oldest are dropped and counted")
    stop_with: list[str] = opt(default_factory=list, help="end when one of these services (e.g. executor) "
                               "disappears after it was seen (comma-separated; how a compose run ends)")
    log_level: str = opt("INFO", help="logging level", choices=LOG_LEVELS)

    def validate(self) -> None:
        """Check the options."""
        if not str(self.model):
            raise ConfigError("predictor.model: must name a model file")
        if self.unfamiliar not in UNFAMILIAR:
            raise ConfigError(f"predictor.unfamiliar: one of {', '.join(UNFAMILIAR)}, got {self.unfamiliar!r}")
        if self.evidence not in ("sum", "mean"):
            raise ConfigError(f"predictor.evidence: 'sum' or 'mean', got {self.evidence!r}")
        if not (self.temperature >= 0 and np.isfinite(self.temperature)):
            raise ConfigError(f"predictor.temperature: must be >= 0 (0 = the model's), got {self.temperature}")
        if self.evidence == "mean" and self.temperature == 0:
            # the model's tau is chosen on summed evidence; dividing that by the frames as well left every
            # posterior within 0.01 of uniform (the paper's library: 0.134 against 0.125)
            raise ConfigError("predictor.evidence 'mean' needs predictor.temperature set: the model's temperature "
                              "is chosen for summed evidence (the authors' code, which takes the mean, uses 1)")
        if not (0 <= self.grid_interval_s <= 10 and np.isfinite(self.grid_interval_s)):
            raise ConfigError(f"predictor.grid_interval_s: must be in [0, 10] s, got {self.grid_interval_s}")
        if not (isinstance(self.backlog, int) and 1 <= self.backlog <= 1_000_000):
            raise ConfigError(f"predictor.backlog: must be an integer in [1, 1000000], got {self.backlog!r}")


@dataclass
class PredictionResult:
    """The prediction after one posture.

    Attributes:
        posterior: ``(M,)`` class posteriors p(C_m | xi) (at the core's temperature), summing to 1.
        log_likelihood: ``(M,)`` ln p(xi | C_m) of the observed prefix.
        grid: The voxel grid.
        method: ``"prediction"`` or ``"current"``.
        indices: ``(N,)`` flat C-order indices of the voxels the prediction covers: the union of the class volumes
            (``prediction``; a voxel may have probability 0 under this posterior) or the current posture's voxels.
        values: ``(N,)`` float32 their probability.

    ``indices`` and ``values`` are read-only: they may be the core's own arrays (the union, the all-classes
    occupancy), which a caller editing them would change for every later prediction. Copy them to edit.
        n_observed: Number of postures observed in this demonstration.
        familiarity: How well the best class explains the last frames (nats per frame,
            :mod:`services.predictor.novelty`).
        familiar: Whether that is at or above the model's novelty threshold (always, for a model without one).
    """

    posterior: np.ndarray
    log_likelihood: np.ndarray
    grid: Grid
    method: str
    indices: np.ndarray
    values: np.ndarray
    n_observed: int
    familiarity: float = 0.0
    familiar: bool = True

    @property
    def occupancy(self) -> np.ndarray:
        """``(nx, ny, nz)`` float32 dense occupancy in [0, 1]."""
        out = np.zeros(int(np.prod(self.grid.dims)), dtype=np.float32)
        out[self.indices] = self.values
        return out.reshape(self.grid.dims)

    def to_message(self, **meta: object) -> OccupancyGrid:
        """The quantised sparse :class:`OccupancyGrid` (same result as ``OccupancyGrid.from_dense``).

        Args:
            **meta: stamp, tick, tick_last, demo_id, index.
        """
        q = np.rint(np.clip(self.values, 0.0, 1.0) * np.float32(255.0)).astype(np.uint8)
        keep = q > 0
        return OccupancyGrid(resolution=float(self.grid.resolution), origin=np.asarray(self.grid.min, np.float64),
                             dims=np.asarray(self.grid.dims, dtype=np.int32),
                             indices=self.indices[keep].astype(np.uint32), values=q[keep], method=self.method,
                             **meta)  # type: ignore[arg-type]


class PredictorCore:
    """Incremental recognition and occupancy prediction for one observed human.

    Args:
        model: Trained prediction model.
        scene: Scene (must place the human where the model's volumes were computed).
        config: Options (method, temperature).

    Raises:
        ModelError: If the model has no swept volumes (its features have no mapping to the human model).
        MappingError: If its features are not the ones ``HumanPose`` carries.
    """

    def __init__(self, model: PredictionModel, scene: Scene, config: PredictorConfig | None = None) -> None:
        self.model = model
        self.scene = scene
        self.config = config or PredictorConfig()
        try:  # a config built in code, not read from a file, is checked as well
            self.config.validate()
        except ConfigError as exc:
            raise PredictorError(str(exc)) from None
        if self.config.method not in METHODS:
            raise PredictorError(f"method {self.config.method!r} is not one of {', '.join(METHODS)}")
        tau = float(self.config.temperature or model.temperature)
        if not (tau > 0 and np.isfinite(tau)):
            raise PredictorError(f"temperature must be a finite number > 0, got {tau}")
        volumes = model.require_volumes("foresight predictor (occupancy)")
        require_mapping(model.feature_names, "foresight predictor (HumanPose messages)",
                        f"model of {model.meta.get('library', '?')}", exact=LIVE_MAPPING)
        model.check_scene(scene)
        self.temperature = tau
        self.bank = model.bank()
        self.encoder = model.encoder()
        self.human = HumanModel()
        flat = volumes.reshape(model.n_classes, -1)
        self.support = _read_only(np.flatnonzero(flat.any(axis=0)))          # (U,) union of the volumes
        self.volumes_u = np.ascontiguousarray(flat[:, self.support], dtype=np.float32)  # (M, U)
        self.timed_u: np.ndarray | None = None                               # (B, M, U): p(x|C_m, t) per time bin
        if model.timed is not None:
            pos = np.searchsorted(model.timed.support, self.support)
            self.timed_u = np.ascontiguousarray(np.swapaxes(model.timed.values[:, :, pos], 0, 1), dtype=np.float32)
        self.demo_id = -1
        self._ll = np.zeros(model.n_classes)
        self._first: np.ndarray | None = None
        self._last: tuple[np.ndarray, int, np.ndarray] | None = None  # the last posture, its index, the posterior
        self._count = 0
        self.novelty = model.novelty
        self._window = FamiliarityWindow(model.novelty.window if model.novelty is not None else DEFAULT_WINDOW)
        self._familiarity = 0.0
        # every class's volume at once: the occupancy of a motion no class explains (unfamiliar = all-classes)
        self._all_u: np.ndarray | None = None

    @property
    def n_observed(self) -> int:
        """Postures observed since the last reset."""
        return self._count

    def reset(self, demo_id: int) -> None:
        """Start observing a new demonstration (clears the likelihoods and the first pose)."""
        self.demo_id = int(demo_id)
        self._ll = np.zeros(self.model.n_classes)
        self._first = None
        self._last = None
        self._count = 0
        self.encoder.reset()
        self._window.reset()
        self._familiarity = 0.0

    @property
    def familiarity(self) -> float:
        """The familiarity after the last observed posture (nats per frame; 0 before any)."""
        return self._familiarity

    @property
    def familiar(self) -> bool:
        """Whether the motion so far is familiar: its familiarity at or above the model's novelty threshold.

        Judged from the :data:`~services.predictor.novelty.MIN_FRAMES`-th posture on.
        """
        return self.novelty is None or self._count < MIN_FRAMES or self._familiarity >= self.novelty.threshold

    def log_likelihood(self) -> np.ndarray:
        """``(M,)`` running ln p(xi | C_m)."""
        return self._ll.copy()

    def occupancy_for(self, posterior: np.ndarray, index: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Predicted occupancy ``sum_m p(x|C_m) p(C_m|xi)`` for given class posteriors.

        Args:
            posterior: ``(M,)`` class probabilities.
            index: The observed sample index t (a ``timed`` model gives ``p(x|C_m, t)``: what is still to
                come; other models ignore it).

        Returns:
            ``(indices (U,), values (U,) float32)``: flat voxel indices (the union of the swept
            volumes, the core's read-only array) and their probabilities.
        """
        vol = self.volumes_u if self.timed_u is None else self.timed_u[self.model.timed.bin(index)]  # type: ignore
        val = np.asarray(posterior, dtype=np.float32) @ vol
        return self.support, np.minimum(val, np.float32(1.0))

    def observe(self, features: np.ndarray, index: int | None = None) -> np.ndarray:
        """Observe one posture: update the recognition only (the cheap part of :meth:`update`).

        A service that falls behind its pose stream observes every pose (no evidence is lost) and
        calls :meth:`predict` for the newest one only.

        Args:
            features: ``(12,)`` recorder-frame posture.
            index: Its sample index in the demonstration (default: the number observed so far).

        Returns:
            ``(M,)`` the class posterior p(C_m | xi) after it.

        Raises:
            PredictorError: If ``features`` is not 12 finite numbers, one is outside its plausible range
                (``shared.feature_sets.HERAKLES_RANGES``, as on the wire), or ``index`` is not a whole number after
                the last observed one (a duplicate pose counted its evidence twice).
        """
        f = np.asarray(features, dtype=np.float64)
        if f.shape != (12,) or not np.all(np.isfinite(f)):
            raise PredictorError(f"features: expected 12 finite numbers, got shape {f.shape}"
                                 + ("" if f.shape != (12,) else " with NaN/inf"))
        out = herakles_out_of_range(f)  # an absurd posture would make every class's evidence -inf for good
        if out:
            raise PredictorError(f"features: {out}; the posture is not observed")
        if index is not None and (isinstance(index, bool) or not isinstance(index, (int, np.integer))):
            raise PredictorError(f"index must be a whole number, got {index!r}")  # 2.7, "5", NaN: taken, or a crash
        t = self._count if index is None else int(index)
        if t < 0 or (self._last is not None and t <= self._last[1]):  # a repeat or a step back counted twice
            raise PredictorError(f"index must be >= 0, got {t}" if t < 0 else f"index {t} is not after the last "
                                 f"observed ({self._last[1]}): a demonstration's poses come in order; a new one "
                                 "starts with a reset")
        if self._first is None:
            self._first = f.copy()
        x = self.encoder.step(f, t)
        frame = self.bank.log_likelihood(x[None])[0]
        self._ll = self._ll + frame
        self._familiarity = self._window.push(frame)
        self._count += 1
        ll = self._ll / self._count if self.config.evidence == "mean" else self._ll
        self._last = (f, t, posterior_from_log_likelihood(ll, temperature=self.temperature))
        return self._last[2]

    def predict(self) -> PredictionResult:
        """The prediction after the last observed posture (:meth:`observe`).

        Raises:
            PredictorError: If nothing was observed since the last reset.
        """
        if self._last is None or self._first is None:
            raise PredictorError("predict: no posture observed since the last reset")
        f, t, post = self._last
        if self.config.method == "prediction" and self.config.unfamiliar == "all-classes" and not self.familiar:
            idx, val = self.support, self.every_class(t)
        elif self.config.method == "prediction":
            idx, val = self.occupancy_for(post, t)
        else:
            placed = place_in_scene(f, self._first, self.scene)
            idx = posture_voxels(self.human.surface_points(placed, spacing=self.model.spacing,
                                                           interior=self.model.interior), self.model.grid)
            val = np.ones(len(idx), dtype=np.float32)
        return PredictionResult(post, self._ll.copy(), self.model.grid, self.config.method, _read_only(idx),
                                _read_only(val), self._count, self._familiarity, self.familiar)

    def every_class(self, index: int = 0) -> np.ndarray:
        """``(U,)`` float32 ``max_m p(x|C_m)`` over the support: every known class's volume at once (read-only).

        Args:
            index: The observed sample index (a ``timed`` model: what is still to come of every class).
        """
        if self.timed_u is not None:
            return self.timed_u[self.model.timed.bin(index)].max(axis=0)  # type: ignore[union-attr]
        if self._all_u is None:
            self._all_u = _read_only(self.volumes_u.max(axis=0))  # cached: shared by every prediction
        return self._all_u

    def update(self, features: np.ndarray, index: int | None = None) -> PredictionResult:
        """Observe one posture and predict (:meth:`observe` then :meth:`predict`).

        Args:
            features: ``(12,)`` recorder-frame posture.
            index: Its sample index in the demonstration (default: the number observed so far).

        Returns:
            The updated prediction.

        Raises:
            PredictorError: If ``features`` is not 12 finite numbers, one is outside its plausible range
                (``shared.feature_sets.HERAKLES_RANGES``, as on the wire), or ``index`` is not after the last one.
        """
        self.observe(features, index)
        return self.predict()
