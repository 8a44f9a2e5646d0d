"""A motion library's contents: demonstrations of M classes, the issues found reading them, and splits.

A *library* holds M motion classes, each with several *demonstrations* (recorded motions of T
samples of F joint features). The library declares its features (``MotionLibrary.feature_names``):
the paper's 12 (:data:`FEATURE_NAMES`, the HERAKLES human model's joints) or any other fixed set
(``shared.feature_sets``: recognition works on any set, the occupancy needs a mapping to the human
model).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shared.feature_sets import HERAKLES_NAMES, HERAKLES_RANGES, HERAKLES_UNITS, FeatureMapping, mapping_for

__all__ = ["FEATURE_NAMES", "FEATURE_UNITS", "PLAUSIBLE_RANGES", "NO_VALID_DEMONSTRATION", "LibraryError",
           "Demonstration", "LibraryIssue", "MotionLibrary", "heldout_split"]

FEATURE_NAMES: tuple[str, ...] = HERAKLES_NAMES
"""The paper's 12 features of a posture, in its (and its CSV's) order (``shared.feature_sets``)."""

FEATURE_UNITS: tuple[str, ...] = HERAKLES_UNITS

PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = HERAKLES_RANGES
"""Per-feature ``(low, high)`` bounds of a plausible human posture (recorder frame)."""


NO_VALID_DEMONSTRATION = "holds no valid demonstration"
"""The end of a class file's summary issue, said after the issues that left it empty (not one of them)."""


class LibraryError(ValueError):
    """A library file or directory is missing or unreadable; the message names it."""


@dataclass(frozen=True)
class Demonstration:
    """One recorded motion.

    Attributes:
        label: Class index ``0..M-1``.
        class_name: Name of the class (the CSV file's stem, e.g. ``compound_3``).
        index: Index of the demonstration within its class, counting valid ones only (0, 1, ...).
        features: ``(T, F)`` float64 features in the recorder's frame, order ``MotionLibrary.feature_names``.
        source: Where it came from, e.g. ``compound_3.csv#block 4``.
    """

    label: int
    class_name: str
    index: int
    features: np.ndarray
    source: str

    @property
    def n_samples(self) -> int:
        """Number of samples T."""
        return int(self.features.shape[0])


@dataclass(frozen=True)
class LibraryIssue:
    """A malformed demonstration left out of the library.

    Attributes:
        class_name: Class (file) it was found in.
        block: 0-based index of the block of rows within the class file (counting every block,
            valid or not); -1 for a problem with the whole file.
        reason: What rule it broke, with line numbers.
    """

    class_name: str
    block: int
    reason: str

    def __str__(self) -> str:
        where = "whole file" if self.block < 0 else f"block {self.block}"
        return f"{self.class_name} {where}: {self.reason}"

    @property
    def summary(self) -> bool:
        """Whether this is a class file's "holds no valid demonstration" line, a sum of its other issues."""
        return self.block < 0 and self.reason.endswith(NO_VALID_DEMONSTRATION)


@dataclass
class MotionLibrary:
    """Demonstrations of M classes plus the issues found while reading them.

    Attributes:
        class_names: M class names; ``class_names[label]``.
        demos: Valid demonstrations, ordered by (label, index).
        issues: Malformed demonstrations that were left out.
        source: Path the library was read from (or a description for generated ones).
        feature_names: The F features of every demonstration, in column order (default: the paper's 12).
        origin: What a converted library (an ``.npz``) was converted from, as it was written ("" otherwise).
    """

    class_names: list[str]
    demos: list[Demonstration]
    issues: list[LibraryIssue] = field(default_factory=list)
    source: str = ""
    feature_names: tuple[str, ...] = FEATURE_NAMES
    origin: str = ""

    @property
    def n_classes(self) -> int:
        """Number of classes M."""
        return len(self.class_names)

    @property
    def n_features(self) -> int:
        """Number of features F."""
        return len(self.feature_names)

    @property
    def mapping(self) -> FeatureMapping | None:
        """The mapping of the features to the human model (None: recognition only)."""
        return mapping_for(self.feature_names)

    def by_class(self, label: int) -> list[Demonstration]:
        """The valid demonstrations of class ``label``, in index order."""
        return [d for d in self.demos if d.label == label]

    def counts(self) -> list[int]:
        """Number of valid demonstrations per class."""
        out = [0] * self.n_classes
        for d in self.demos:
            out[d.label] += 1
        return out


def heldout_split(lib: MotionLibrary, n_per_class: int, seed: int
                  ) -> tuple[list[Demonstration], list[Demonstration]]:
    """Split the library into training and held-out demonstrations, ``n_per_class`` held out per class.

    The choice depends only on ``seed`` and the library (one ``numpy.random.default_rng(seed)``
    draws the held-out indices of class 0, then class 1, ...).

    Args:
        lib: The library.
        n_per_class: Demonstrations held out per class (>= 0, fewer than the class has).
        seed: Random seed.

    Returns:
        ``(train, heldout)``, both ordered by (label, index).

    Raises:
        LibraryError: If ``n_per_class`` is negative or leaves a class without training data, or ``seed`` is not an
            integer >= 0.
    """
    if n_per_class < 0:
        raise LibraryError(f"heldout: n_per_class must be >= 0, got {n_per_class}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise LibraryError(f"heldout: the seed must be an integer >= 0, got {seed!r}")  # numpy's error named no option
    rng = np.random.default_rng(seed)
    train: list[Demonstration] = []
    held: list[Demonstration] = []
    for label in range(lib.n_classes):
        demos = lib.by_class(label)
        if n_per_class and n_per_class >= len(demos):
            raise LibraryError(f"heldout: class {lib.class_names[label]} has {len(demos)} valid demonstrations, "
                               f"cannot hold out {n_per_class} and keep any for training")
        chosen = set(rng.choice(len(demos), size=n_per_class, replace=False).tolist()) if n_per_class else set()
        for i, d in enumerate(demos):
            (held if i in chosen else train).append(d)
    return train, held
