"""Feature sets of motion libraries and their mappings to the human model.

A library's demonstrations are ``(T, F)`` arrays of F joint features; the library declares F (the
CSV's column count minus the index column, or the npz's ``feature_names``). Recognition needs
nothing more: the class mixtures, their posteriors, ``foresight eval recognition`` and the
mixtures of ``foresight train`` work on any fixed F.

Whatever places a human in the scene (swept volumes, occupancy, the live pipeline) needs a
:class:`FeatureMapping`: which features a library has and how they drive the human model
(:class:`shared.human.HumanModel`, whose joints are the paper's 12 features). A library's mapping
is found by its feature names (:func:`mapping_for`). One mapping ships: :data:`HERAKLES`, the
paper's 12 features (the columns of its CSV files), which drive the HERAKLES model directly. A
library with another feature set has no mapping; the commands that need one fail with one line
(:func:`require_mapping`). Adding a mapping means one :class:`FeatureMapping` (names, units,
plausible ranges and ``to_human``) and one entry in :data:`MAPPINGS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "HERAKLES_NAMES",
    "HERAKLES_UNITS",
    "HERAKLES_RANGES",
    "herakles_out_of_range",
    "FeatureMapping",
    "HERAKLES",
    "MAPPINGS",
    "MappingError",
    "generic_names",
    "mapping_for",
    "describe_features",
    "count_features",
    "require_mapping",
    "LIVE_MAPPING",
]

HERAKLES_NAMES: tuple[str, ...] = (
    "pelvis_x",
    "pelvis_y",
    "pelvis_z",
    "pelvis_yaw",
    "torso_x",
    "torso_y",
    "torso_z",
    "r_shoulder_x",
    "r_shoulder_z",
    "r_shoulder_y",
    "r_arm_trans",
    "r_elbow_z",
)
"""The paper's 12 features of a posture, in its (and its CSV's) order."""

HERAKLES_UNITS: tuple[str, ...] = ("m", "m", "m", "rad", "rad", "rad", "rad", "rad", "rad", "rad", "m", "rad")

_TWO_PI = 2.0 * math.pi
HERAKLES_RANGES: dict[str, tuple[float, float]] = {
    # the recorder's room: a person stands within a few metres of the camera
    "pelvis_x": (-10.0, 10.0),
    "pelvis_y": (-10.0, 10.0),
    # pelvis height of a standing or sitting adult
    "pelvis_z": (0.3, 1.6),
    # angles: one turn either way (recorded angles are not wrapped)
    "pelvis_yaw": (-_TWO_PI, _TWO_PI),
    "torso_x": (-_TWO_PI, _TWO_PI),
    "torso_y": (-_TWO_PI, _TWO_PI),
    "torso_z": (-_TWO_PI, _TWO_PI),
    "r_shoulder_x": (-_TWO_PI, _TWO_PI),
    "r_shoulder_z": (-_TWO_PI, _TWO_PI),
    "r_shoulder_y": (-_TWO_PI, _TWO_PI),
    # prismatic joint that lengthens the upper arm: a few centimetres, never half a metre
    "r_arm_trans": (-0.5, 0.5),
    "r_elbow_z": (-_TWO_PI, _TWO_PI),
}
"""Per-feature ``(low, high)`` bounds of a plausible human posture (recorder frame)."""


def herakles_out_of_range(features: np.ndarray) -> str | None:
    """The first of the paper's 12 features outside its plausible range (:data:`HERAKLES_RANGES`), described.

    Args:
        features: ``(12,)`` a posture in the paper's feature order.

    Returns:
        ``"<name> = <value> outside its plausible range [low, high]"``, or None when every feature is inside.
    """
    for name, value in zip(HERAKLES_NAMES, np.asarray(features, dtype=np.float64), strict=True):
        low, high = HERAKLES_RANGES[name]
        if not low <= value <= high:
            return f"{name} = {value:.6g} outside its plausible range [{low:.4g}, {high:.4g}]"
    return None


class MappingError(ValueError):
    """A command needs a feature mapping the library (or model) does not have; the message names it."""


@dataclass(frozen=True)
class FeatureMapping:
    """How a feature set drives the human model.

    Attributes:
        name: Short name (the key in :data:`MAPPINGS`).
        description: One line: what the features are.
        feature_names: The F feature names, in column order.
        units: Unit of each feature.
        plausible_ranges: ``name -> (low, high)`` bounds the library validation checks.
        to_human: ``(..., F) -> (..., 12)`` the human model's joint values (``HERAKLES_NAMES`` order).
    """

    name: str
    description: str
    feature_names: tuple[str, ...]
    units: tuple[str, ...]
    plausible_ranges: dict[str, tuple[float, float]]
    to_human: Callable[[np.ndarray], np.ndarray]

    @property
    def n_features(self) -> int:
        """Number of features F."""
        return len(self.feature_names)


def _identity(features: np.ndarray) -> np.ndarray:
    return np.asarray(features, dtype=np.float64)


HERAKLES = FeatureMapping(
    name="herakles",
    description="the paper's 12 features (pelvis x, y, z, yaw, torso X, Y, Z, right shoulder X, Z, Y, arm "
                "translation, elbow Z), the joints of the HERAKLES human model",
    feature_names=HERAKLES_NAMES,
    units=HERAKLES_UNITS,
    plausible_ranges=HERAKLES_RANGES,
    to_human=_identity,
)

MAPPINGS: dict[str, FeatureMapping] = {HERAKLES.name: HERAKLES}
"""Every known mapping, by name."""

LIVE_MAPPING = HERAKLES
"""The feature set the live pipeline streams: ``HumanPose.features`` carries exactly these features."""


def generic_names(n: int) -> tuple[str, ...]:
    """Names of ``n`` features read without a declared feature set: ``feature_1 .. feature_n`` (CSV column)."""
    return tuple(f"feature_{j}" for j in range(1, n + 1))


def mapping_for(feature_names: tuple[str, ...] | list[str]) -> FeatureMapping | None:
    """The mapping whose feature names are exactly ``feature_names`` (None: the features have none)."""
    names = tuple(feature_names)
    return next((m for m in MAPPINGS.values() if m.feature_names == names), None)


def _span(names: tuple[str, ...]) -> str:
    return ", ".join(names) if len(names) <= 3 else f"{names[0]} .. {names[-1]}"


def count_features(feature_names: tuple[str, ...] | list[str]) -> str:
    """``"16 features (feature_1 .. feature_16)"``."""
    names = tuple(feature_names)
    return f"{len(names)} features ({_span(names)})"


def describe_features(feature_names: tuple[str, ...] | list[str]) -> str:
    """One line: how many features, which, and their mapping (or that there is none)."""
    names = tuple(feature_names)
    mapping = mapping_for(names)
    if mapping is not None:
        return f"{len(names)} (mapping {mapping.name}: {_span(names)})"
    return f"{len(names)} ({_span(names)}; no mapping to the human model: recognition only)"


def require_mapping(feature_names: tuple[str, ...] | list[str], what: str, source: str = "",
                    exact: FeatureMapping | None = None) -> FeatureMapping:
    """The mapping of ``feature_names``, or a one-line :class:`MappingError` naming what is missing.

    Args:
        feature_names: The library's (or model's) feature names.
        what: What needs the mapping, e.g. ``"foresight replayer (HumanPose carries the herakles features)"``.
        source: The library or model, for the message (e.g. ``"library 'wide/'"``).
        exact: Require this mapping's feature set itself (e.g. :data:`LIVE_MAPPING` for what
            ``HumanPose`` carries, or code that indexes the paper's columns).

    Returns:
        The mapping.

    Raises:
        MappingError: If there is none (or, with ``exact``, it is another one).
    """
    names = tuple(feature_names)
    mapping = mapping_for(names)
    if mapping is not None and (exact is None or mapping is exact):
        return mapping
    has = count_features(names)
    need = (f"the {exact.name} feature set ({exact.n_features} features: {_span(exact.feature_names)})" if exact
            else f"a mapping from the features to the human model (known: {', '.join(MAPPINGS)})")
    raise MappingError(f"{what} needs {need}; {source or 'the library'} has {has} "
                       f"{'with mapping ' + mapping.name if mapping else 'and no mapping'} "
                       "(recognition, `foresight train` and `foresight eval recognition`, works without one)")
