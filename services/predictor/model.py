"""The prediction model file: everything the predictor needs, in one versioned ``.npz`` (no pickles).

Contents (M classes, K Gaussians at most per class, F posture features, D feature dimensions, V voxels):

| key | dtype, shape | meaning |
|---|---|---|
| ``format`` | str | ``"foresight-prediction-model"`` |
| ``version`` | int | :data:`MODEL_VERSION` |
| ``class_names`` | str (M,) | class names |
| ``feature_variant`` | str | ``services.predictor.features`` variant |
| ``time_scale``, ``velocity_scale`` | float | feature scaling |
| ``weights`` | f8 (M, K) | mixing weights (0: padding) |
| ``means`` | f8 (M, K, D) | component means |
| ``covariances`` | f8 (M, K, D, D) | full covariances |
| ``feature_names`` | str (F,) | the library's posture features (optional: files without it have the paper's 12) |
| ``motions`` | f8 (M, T, F) | GMR-regressed motion of each class |
| ``motion_lengths`` | i8 (M,) | valid postures of each motion (rest is padding) |
| ``grid_min``, ``grid_max`` | f8 (3,) | grid bounds (scene frame) |
| ``grid_resolution`` | float | voxel edge (m) |
| ``volumes`` | u1 (M, ceil(V/8)) | ``paper`` volumes: ``numpy.packbits`` of the C-order bool grids; absent when the
  features have no mapping to the human model (a recognition-only model, ``shared.feature_sets``) |
| ``volume_probabilities`` | u1 (M, V) | other volume methods: ``p(x|C_m)`` quantised as ``round(255 p)`` (C order) |
| ``timed_support`` | i4 (U,) | ``timed`` volumes: flat indices of the voxels any class may occupy |
| ``timed_values`` | u1 (M, B, U) | ``timed``: ``p(x|C_m, t)`` per time bin, quantised as ``round(255 p)`` |
| ``time_bin`` | int | ``timed``: samples per time bin (bin b starts at sample ``b * time_bin``) |
| ``volume_method`` | str | ``services.predictor.volumes.VOLUMES`` (optional: files without it are ``paper``) |
| ``scene_name`` | str | scene the volumes were placed in |
| ``human_pelvis`` | f8 (4,) | that scene's human placement (x, y, z, yaw) |
| ``spacing`` | float | surface sample spacing (m) used for the volumes |
| ``interior`` | bool | whether the body's inside was sampled too |
| ``meta`` | str | JSON: library source, demonstrations per class, options, timestamp, ``last_index`` |
| ``temperature`` | float | posterior temperature tau (optional: files without it use 1, the paper's) |
| ``novelty_threshold``, ``novelty_window``, ``novelty_quantile``, ``novelty_heldout`` | f8, i8, f8, i8 | the novelty
  test (:mod:`services.predictor.novelty`; optional: files without it call every motion familiar) |
| ``novelty_sensor_noise_m`` | f8 | the keypoint noise the novelty test was calibrated for (written when not 0; files
  without it: 0, the features as recorded) |
| ``time_from`` | str | where a demonstration's time starts (:data:`TIME_FROM`; written when not ``recording``: files
  without it index from the recording's start) |

Version 2 added ``volume_method``, ``volume_probabilities`` and the ``timed_*`` arrays; version 1 files
(paper volumes) still load.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shared.atomic_file import atomic_write, unreadable
from shared.data_files import relative_to_cwd
from shared.feature_sets import HERAKLES_NAMES, MAPPINGS, count_features, mapping_for
from shared.npz_reading import NPZ_LOCK
from shared.protocol.validation import GridSpec
from shared.scene import Grid, Scene

from .features import FeatureEncoder
from .gmm import MixtureBank
from .novelty import NoveltyTest
from .swept_volume import pack_volumes, unpack_volumes
from .volumes import VOLUMES

__all__ = ["MODEL_FORMAT", "MODEL_VERSION", "TIME_FROM", "ModelError", "PredictionModel", "TimedVolumes", "to_bytes",
           "from_bytes", "quantised"]

MODEL_FORMAT = "foresight-prediction-model"
MODEL_VERSION = 2
READABLE_VERSIONS = (1, 2)
TIME_FROM = ("recording", "tracker")
"""Sample 0 of a training demonstration: the recording's first, or where the tracker's reach rule starts its reach."""


def to_bytes(p: np.ndarray) -> np.ndarray:
    """Probabilities in [0, 1] as the file stores them: ``round(255 p)`` as uint8 (same shape)."""
    return np.rint(np.clip(p, 0.0, 1.0) * 255.0).astype(np.uint8)


def from_bytes(q: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_bytes`: uint8 -> float32 ``q / 255``."""
    return q.astype(np.float32) / np.float32(255.0)


def quantised(p: np.ndarray) -> np.ndarray:
    """``p`` as a saved and loaded model holds it (the trainer applies it, so a model equals its file)."""
    return from_bytes(to_bytes(p))


class ModelError(ValueError):
    """A model file is missing, corrupt, of another version or inconsistent; the message says which."""


@dataclass(frozen=True)
class TimedVolumes:
    """Time-indexed class volumes ``p(x|C_m, t)`` (the ``timed`` method) over the voxels U any class may occupy.

    Attributes:
        support: ``(U,)`` flat C-order voxel indices.
        values: ``(M, B, U)`` float32: the probability that a demonstration of class m occupies the voxel at a
            sample index >= ``b * time_bin``.
        time_bin: Samples per bin.
    """

    support: np.ndarray
    values: np.ndarray
    time_bin: int

    def bin(self, index: int) -> int:
        """The bin of sample ``index`` (the last one for indices past the longest demonstration)."""
        return min(max(int(index), 0) // self.time_bin, self.values.shape[1] - 1)


@dataclass
class PredictionModel:
    """Trained per-class mixtures, regressed motions and swept volumes on one voxel grid.

    ``volumes`` (``p(x|C_m)`` in [0, 1]; 0/1 for the paper's method) is None for a model of features
    without a mapping to the human model: it recognises (mixtures, posteriors) but predicts no
    occupancy (:meth:`require_volumes`).
    """

    class_names: list[str]
    feature_variant: str
    time_scale: float
    velocity_scale: float
    weights: np.ndarray        # (M, K)
    means: np.ndarray          # (M, K, D)
    covariances: np.ndarray    # (M, K, D, D)
    motions: np.ndarray        # (M, T, F)
    motion_lengths: np.ndarray  # (M,)
    grid: Grid
    volumes: np.ndarray | None  # (M, nx, ny, nz) float32 in [0, 1]; None without a feature mapping
    scene_name: str
    human_pelvis: np.ndarray   # (4,) x, y, z, yaw
    spacing: float = 0.02
    interior: bool = False
    meta: dict[str, Any] = field(default_factory=dict)
    temperature: float = 1.0
    feature_names: tuple[str, ...] = HERAKLES_NAMES
    volume_method: str = "paper"
    timed: TimedVolumes | None = None
    novelty: NoveltyTest | None = None
    time_from: str = "recording"

    @property
    def n_classes(self) -> int:
        """Number of classes M."""
        return len(self.class_names)

    def bank(self) -> MixtureBank:
        """The class mixtures, stacked for scoring."""
        return MixtureBank(self.weights, self.means, self.covariances)

    def encoder(self) -> FeatureEncoder:
        """A fresh feature encoder matching the training features."""
        return FeatureEncoder(self.feature_variant, self.time_scale, self.velocity_scale, self.feature_names,
                              last_index=self.last_index)

    @property
    def last_index(self) -> int:
        """The last sample index the mixtures were fitted on (``meta["last_index"]``).

        A model trained before it was recorded: the last sample of its longest class motion.
        """
        return int(self.meta.get("last_index", int(np.max(self.motion_lengths)) - 1))

    def describe_time(self) -> str:
        """Where the mixtures' time starts, for ``foresight train``'s output and the predictor's start line."""
        if self.time_from == "tracker":
            return "time from where the tracker's reach rule starts each demonstration (a live person's reach)"
        return "time from each demonstration's first sample, at rest (the replayer's reach)"

    def require_volumes(self, what: str) -> np.ndarray:
        """The ``(M, nx, ny, nz)`` swept volumes, or a one-line :class:`ModelError` saying why there are none.

        Args:
            what: What needs them, e.g. ``"foresight predictor"``.
        """
        if self.volumes is None:
            raise ModelError(f"{what} needs a model with swept volumes; this one was trained on library "
                             f"{self.meta.get('library', '?')}, whose {count_features(self.feature_names)} have no "
                             f"mapping to the human model (known: {', '.join(MAPPINGS)}): it only recognises classes")
        return self.volumes

    def motion(self, m: int) -> np.ndarray:
        """``(T_m, F)`` regressed motion of class ``m``."""
        return self.motions[m, : int(self.motion_lengths[m])]

    def check_scene(self, scene: Scene) -> None:
        """Raise :class:`ModelError` if ``scene`` places the human elsewhere than the training scene."""
        pelvis = np.array([*scene.human.pelvis_xyz, scene.human.pelvis_yaw])
        if not np.allclose(pelvis, self.human_pelvis, atol=1e-6):
            raise ModelError(f"model: its swept volumes were computed for the human of scene {self.scene_name!r} at "
                             f"{np.round(self.human_pelvis, 3).tolist()}, scene {scene.name!r} places the human at "
                             f"{np.round(pelvis, 3).tolist()}; retrain with `foresight train --scene ...`")

    def check_planner_grid(self, scene: Scene) -> None:
        """Raise :class:`ModelError` if the planner of ``scene`` would refuse the occupancy on the model's grid.

        The planner takes the scene grid's bounds, no finer than half its resolution (``GridSpec.planning``).
        Before, a predictor service with a model on another grid started, and the planner refused every occupancy
        it published. (An experiment scoring occupancy offline may use any grid: only the service checks.)
        """
        wrong = GridSpec.planning(scene.grid).mismatch(self.grid.min, self.grid.dims, self.grid.resolution)
        if wrong is not None:
            raise ModelError(f"model: its grid ({wrong[0]}: {wrong[1]}) is not one the planner of scene {scene.name!r} "
                             f"takes (its grid {scene.grid.min.tolist()}..{scene.grid.max.tolist()} at "
                             f"{scene.grid.resolution:g} m, no finer than half that); retrain with `foresight train "
                             "--scene ...`")

    # ---- file --------------------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        """Write the model file (compressed npz)."""
        p = Path(path)
        arrays = {
            "format": np.array(MODEL_FORMAT), "version": np.array(MODEL_VERSION, dtype=np.int64),
            "class_names": np.array(self.class_names, dtype=np.str_),
            "feature_variant": np.array(self.feature_variant),
            "time_scale": np.array(self.time_scale), "velocity_scale": np.array(self.velocity_scale),
            "weights": self.weights, "means": self.means, "covariances": self.covariances,
            "motions": self.motions, "motion_lengths": self.motion_lengths.astype(np.int64),
            "grid_min": self.grid.min, "grid_max": self.grid.max, "grid_resolution": np.array(self.grid.resolution),
            "scene_name": np.array(self.scene_name),
            "human_pelvis": self.human_pelvis, "spacing": np.array(self.spacing),
            "interior": np.array(self.interior), "meta": np.array(json.dumps(self.meta)),
            "temperature": np.array(float(self.temperature)),
            "feature_names": np.array(self.feature_names, dtype=np.str_),
            "volume_method": np.array(self.volume_method),
        }
        if self.timed is not None:
            arrays["timed_support"] = self.timed.support.astype(np.int32)
            arrays["timed_values"] = to_bytes(self.timed.values)
            arrays["time_bin"] = np.array(int(self.timed.time_bin), dtype=np.int64)
        elif self.volumes is not None and self.volume_method == "paper":
            arrays["volumes"] = pack_volumes(self.volumes > 0.5)
        elif self.volumes is not None:
            arrays["volume_probabilities"] = to_bytes(self.volumes).reshape(self.n_classes, -1)
        if self.novelty is not None:
            arrays["novelty_threshold"] = np.array(float(self.novelty.threshold))
            arrays["novelty_window"] = np.array(int(self.novelty.window), dtype=np.int64)
            arrays["novelty_quantile"] = np.array(float(self.novelty.quantile))
            arrays["novelty_heldout"] = np.array(int(self.novelty.heldout), dtype=np.int64)
            if self.novelty.sensor_noise_m:  # absent at 0: a model calibrated as before is the same file
                arrays["novelty_sensor_noise_m"] = np.array(float(self.novelty.sensor_noise_m))
        if self.time_from != "recording":  # absent at the default: a model trained as before is the same file
            arrays["time_from"] = np.array(self.time_from)
        with atomic_write(p) as f:  # an interrupted save leaves no half model in the cache
            np.savez_compressed(f, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> PredictionModel:
        """Read and validate a model file.

        Raises:
            ModelError: If the file is missing, not a model file, of another version, or corrupt.
        """
        p = Path(path)
        if p.is_dir():
            raise ModelError(f"model file {str(p)!r} is a directory; give the model file itself (foresight train "
                             "--out FILE writes one)")
        if not p.is_file():
            raise ModelError(f"model file {str(p)!r} not found{relative_to_cwd(p)}; run `foresight train --out {p}` "
                             "first")
        if why := unreadable(p):
            raise ModelError(f"model file {str(p)!r}: {why}; run as its owner or chmod a+r it")
        try:
            with NPZ_LOCK:
                z = np.load(p, allow_pickle=False)
                if not isinstance(z, np.lib.npyio.NpzFile):  # np.save's one array
                    raise ModelError(f"model file {str(p)!r} holds one numpy array ({z.dtype} {z.shape}), not a "
                                     "model (foresight train writes an .npz of many)")
                with z:
                    data = {k: z[k] for k in z.files}
        except ModelError:
            raise
        except (zipfile.BadZipFile, zlib.error, OSError, ValueError, EOFError, MemoryError) as exc:
            raise ModelError(f"model file {str(p)!r} is corrupt or not a model file ({type(exc).__name__}: "
                             f"{str(exc)[:200]}); retrain with `foresight train`") from None
        if str(data.get("format", "")) != MODEL_FORMAT:
            raise ModelError(f"model file {str(p)!r} is not a Foresight prediction model (format "
                             f"{str(data.get('format', 'missing'))!r})")
        raw = data.get("version")
        version = int(raw) if raw is not None and raw.dtype.kind in "iu" and raw.shape == () else (
            None if raw is None else str(raw)[:40])  # 2.9 is not version 2
        if version not in READABLE_VERSIONS:
            raise ModelError(f"model file {str(p)!r} has version {version}, this build reads versions "
                             f"{', '.join(map(str, READABLE_VERSIONS))}; retrain with `foresight train`")
        try:
            return cls._from_arrays(data)
        except KeyError as exc:
            raise ModelError(f"model file {str(p)!r} is inconsistent: it has no array {exc}") from None
        except (ValueError, TypeError, IndexError, AttributeError, OverflowError, MemoryError) as exc:
            raise ModelError(f"model file {str(p)!r} is inconsistent: {str(exc)[:300]}") from None

    @classmethod
    def _from_arrays(cls, d: dict[str, np.ndarray]) -> PredictionModel:
        names = [str(s) for s in np.atleast_1d(d["class_names"]).tolist()]
        m = len(names)
        if m == 0:
            raise ValueError("it has no classes")
        meta = json.loads(str(d["meta"]))
        if not isinstance(meta, dict):
            raise ValueError(f"meta must be a JSON object, got {type(meta).__name__}")
        last = meta.get("last_index", 0)
        if isinstance(last, bool) or not isinstance(last, int) or last < 0:
            raise ValueError(f"meta.last_index must be an integer >= 0, got {str(last)[:40]}")
        for name in ("grid_min", "grid_max"):
            if d[name].shape != (3,) or not np.all(np.isfinite(d[name])):
                raise ValueError(f"{name} must be 3 finite numbers, got {np.array2string(d[name], precision=4)}")
        res = d["grid_resolution"]
        if res.shape != () or not (float(res) > 0 and np.isfinite(float(res))):
            raise ValueError(f"grid_resolution must be a finite number > 0 (m), got {res}")
        if np.any(d["grid_max"] <= d["grid_min"]):
            raise ValueError(f"grid_max {d['grid_max'].tolist()} must exceed grid_min {d['grid_min'].tolist()} on "
                             "every axis")
        if d["interior"].dtype != np.bool_:
            raise ValueError(f"interior must be a boolean, got {d['interior'].dtype} {d['interior']}")
        w, mu, cov = d["weights"], d["means"], d["covariances"]
        if w.shape[0] != m or mu.shape[:2] != w.shape or cov.shape != (*mu.shape, mu.shape[2]):
            raise ValueError(f"mixture shapes {w.shape}, {mu.shape}, {cov.shape} do not fit {m} classes")
        for name, arr in (("weights", w), ("means", mu), ("covariances", cov), ("motions", d["motions"])):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains NaN or infinity")
        sums = w.sum(axis=1)
        if np.any(w < 0) or not np.allclose(sums, 1.0, rtol=0, atol=1e-6):  # else the posterior is NaN at run time
            bad = int(np.flatnonzero(np.any(w < 0, axis=1) | ~np.isclose(sums, 1.0, rtol=0, atol=1e-6))[0])
            raise ValueError(f"class {names[bad]!r}: mixing weights must be >= 0 and sum to 1, got "
                             f"{np.array2string(w[bad], precision=4)} (sum {sums[bad]:.6g})")
        grid = Grid(d["grid_min"].astype(np.float64), d["grid_max"].astype(np.float64), float(d["grid_resolution"]))
        dims = grid.dims
        feature_names = (tuple(str(s) for s in d["feature_names"].tolist()) if "feature_names" in d
                         else HERAKLES_NAMES)
        method = str(d["volume_method"]) if "volume_method" in d else "paper"
        if method == "timed" and "timed_values" not in d:
            raise ValueError("volume method 'timed' but no timed_values / timed_support / time_bin arrays")
        if method not in VOLUMES:
            raise ValueError(f"volume method {method!r} is not one of {', '.join(VOLUMES)}")
        volumes = None
        timed = None
        if "timed_values" in d:
            support, q = d["timed_support"].astype(np.int64), d["timed_values"]
            n = int(np.prod(dims))
            if q.dtype != np.uint8 or q.ndim != 3 or q.shape[0] != m or q.shape[2] != support.shape[0] \
                    or (support.size and (support.min() < 0 or support.max() >= n)) or int(d["time_bin"]) < 1 \
                    or np.any(np.diff(support) <= 0):  # looked up with searchsorted: sorted, each cell once
                raise ValueError(f"timed volumes {q.shape} / support {support.shape} do not fit {m} classes on a "
                                 f"{dims} grid")
            timed = TimedVolumes(support, from_bytes(q), int(d["time_bin"]))
            volumes = np.zeros((m, n), np.float32)
            volumes[:, support] = timed.values[:, 0]
            volumes = volumes.reshape(m, *dims)
        elif "volume_probabilities" in d:
            q = d["volume_probabilities"]
            if q.dtype != np.uint8 or q.shape != (m, int(np.prod(dims))):
                raise ValueError(f"volume probabilities of shape {q.shape} do not fit {m} classes on a {dims} grid")
            volumes = from_bytes(q).reshape(m, *dims)
        elif mapping_for(feature_names) is not None or "volumes" in d:
            packed = d["volumes"]
            if packed.dtype != np.uint8 or packed.shape != (m, (int(np.prod(dims)) + 7) // 8):
                raise ValueError(f"volumes of shape {packed.shape} do not fit {m} classes on a {dims} grid")
            volumes = unpack_volumes(packed, dims).astype(np.float32)
        temperature = float(d["temperature"]) if "temperature" in d else 1.0
        for name, value in (("temperature", temperature), ("time_scale", float(d["time_scale"])),
                            ("velocity_scale", float(d["velocity_scale"])), ("spacing", float(d["spacing"]))):
            if not (value > 0 and np.isfinite(value)):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")
        pelvis = d["human_pelvis"]
        if pelvis.shape != (4,) or not np.all(np.isfinite(pelvis)):
            raise ValueError(f"human_pelvis must be 4 finite numbers (x, y, z, yaw), got shape {pelvis.shape}")
        novelty = None
        if "novelty_threshold" in d:
            noise = float(d["novelty_sensor_noise_m"]) if "novelty_sensor_noise_m" in d else 0.0
            novelty = NoveltyTest(float(d["novelty_threshold"]), int(d["novelty_window"]),
                                  float(d["novelty_quantile"]), int(d["novelty_heldout"]), noise)
        time_from = str(d["time_from"]) if "time_from" in d else "recording"
        if time_from not in TIME_FROM:
            raise ValueError(f"time_from {time_from[:40]!r} is not one of {', '.join(TIME_FROM)}")
        motions = d["motions"].astype(np.float64)
        lengths = d["motion_lengths"].astype(np.int64)
        if motions.shape[0] != m or motions.shape[2] != len(feature_names) or lengths.shape != (m,) \
                or np.any(lengths < 1) or np.any(lengths > motions.shape[1]):
            raise ValueError(f"motions {motions.shape} / lengths {lengths.tolist()} do not fit {m} classes")
        model = cls(class_names=names, feature_variant=str(d["feature_variant"]), time_scale=float(d["time_scale"]),
                    velocity_scale=float(d["velocity_scale"]), weights=w.astype(np.float64),
                    means=mu.astype(np.float64), covariances=cov.astype(np.float64), motions=motions,
                    motion_lengths=lengths, grid=grid, volumes=volumes,
                    scene_name=str(d["scene_name"]), human_pelvis=d["human_pelvis"].astype(np.float64),
                    spacing=float(d["spacing"]), interior=bool(d["interior"]), meta=meta,
                    temperature=temperature, feature_names=feature_names, volume_method=method,
                    timed=timed, novelty=novelty, time_from=time_from)
        if model.encoder().dim != mu.shape[2]:
            raise ValueError(f"feature variant {model.feature_variant!r} has {model.encoder().dim} dimensions, "
                             f"the mixtures {mu.shape[2]}")
        model.bank()  # covariances must be positive definite
        return model
