"""Human-motion libraries: the paper's CSV format, a compact native npz format, and validation.

A *library* holds M motion classes, each with several *demonstrations* (recorded motions of T
samples of the 12 joint features in :data:`FEATURE_NAMES`).

Paper format (a directory of ``compound_<m>.csv``, one file per class, see
``../shared/data/paper-library/README.md``): comma-separated, no header, one posture per row,
demonstrations one after another; column 0 is the sample index within its demonstration (it
returns to 0 where a new demonstration starts), columns 1..12 are the features.

Every demonstration (a *block* of rows) is validated by general rules before it is used:
the row has 13 numeric columns, every value is finite and not subnormal, the index column counts
0, 1, 2, ... without gaps, the block has at least :data:`MIN_SAMPLES` samples and is not much
shorter than its file's other blocks (:data:`TRUNCATED_FRACTION`), no feature is
identically zero over the block (a dead channel) and every feature stays within its plausible
range (:data:`PLAUSIBLE_RANGES`). A block that breaks a rule is left out and reported as a
:class:`LibraryIssue` (class, block index, reason); it never reaches training.

Native format (written by :func:`save_library`): one ``.npz`` without pickles holding the
concatenated features, per-demonstration labels, lengths, indices and sources, the class names
and the issues found when the library was read.
"""

from __future__ import annotations

import math
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "FEATURE_NAMES",
    "FEATURE_UNITS",
    "PLAUSIBLE_RANGES",
    "MIN_SAMPLES",
    "TRUNCATED_FRACTION",
    "NPZ_FORMAT",
    "LibraryError",
    "Demonstration",
    "LibraryIssue",
    "MotionLibrary",
    "load_library",
    "load_csv_class",
    "validate_block",
    "save_library",
    "heldout_split",
]

FEATURE_NAMES: tuple[str, ...] = (
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
"""The 12 features of a posture, in the paper's (and the CSV's) order."""

FEATURE_UNITS: tuple[str, ...] = ("m", "m", "m", "rad", "rad", "rad", "rad", "rad", "rad", "rad", "m", "rad")

_TWO_PI = 2.0 * math.pi
PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
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

MIN_SAMPLES = 10
"""Shortest demonstration accepted (samples)."""

TRUNCATED_FRACTION = 0.5
"""A block shorter than this fraction of its file's median block length is reported as truncated."""

NPZ_FORMAT = 1
"""Version of the native npz layout written by :func:`save_library`."""

_N_COLS = 1 + len(FEATURE_NAMES)
_LOW = np.array([PLAUSIBLE_RANGES[n][0] for n in FEATURE_NAMES])
_HIGH = np.array([PLAUSIBLE_RANGES[n][1] for n in FEATURE_NAMES])
_TINY = np.finfo(np.float64).tiny  # smallest normal float64; non-zero values below it are garbage


class LibraryError(ValueError):
    """A library file or directory is missing or unreadable; the message names it."""


@dataclass(frozen=True)
class Demonstration:
    """One recorded motion.

    Attributes:
        label: Class index ``0..M-1``.
        class_name: Name of the class (the CSV file's stem, e.g. ``compound_3``).
        index: Index of the demonstration within its class, counting valid ones only (0, 1, ...).
        features: ``(T, 12)`` float64 features in the recorder's frame, order :data:`FEATURE_NAMES`.
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


@dataclass
class MotionLibrary:
    """Demonstrations of M classes plus the issues found while reading them.

    Attributes:
        class_names: M class names; ``class_names[label]``.
        demos: Valid demonstrations, ordered by (label, index).
        issues: Malformed demonstrations that were left out.
        source: Path the library was read from (or a description for generated ones).
    """

    class_names: list[str]
    demos: list[Demonstration]
    issues: list[LibraryIssue] = field(default_factory=list)
    source: str = ""

    @property
    def n_classes(self) -> int:
        """Number of classes M."""
        return len(self.class_names)

    def by_class(self, label: int) -> list[Demonstration]:
        """The valid demonstrations of class ``label``, in index order."""
        return [d for d in self.demos if d.label == label]

    def counts(self) -> list[int]:
        """Number of valid demonstrations per class."""
        out = [0] * self.n_classes
        for d in self.demos:
            out[d.label] += 1
        return out


# ----------------------------------------------------------------------------------------------
# validation


def _ranges(mask: np.ndarray) -> str:
    """``[F, F, T, T, F, T]`` -> ``"2-3, 5"`` (0-based positions of True, compressed)."""
    idx = np.flatnonzero(mask)
    parts: list[str] = []
    start = prev = None
    for i in idx.tolist():
        if start is None:
            start = prev = i
        elif i == prev + 1:
            prev = i
        else:
            parts.append(f"{start}" if start == prev else f"{start}-{prev}")
            start = prev = i
    if start is not None:
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
    if len(parts) > 4:
        parts = parts[:4] + ["..."]
    return ", ".join(parts)


def validate_block(features: np.ndarray) -> list[str]:
    """Check one demonstration's features against the library rules.

    Args:
        features: ``(T, 12)`` feature rows of one block.

    Returns:
        Reasons the block is malformed (empty when it is valid). Sample positions are 0-based.
    """
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[1] != len(FEATURE_NAMES):
        return [f"has shape {f.shape}, expected (T, {len(FEATURE_NAMES)})"]
    reasons: list[str] = []
    if f.shape[0] < MIN_SAMPLES:
        reasons.append(f"has {f.shape[0]} samples, fewer than the minimum {MIN_SAMPLES}")
    finite = np.isfinite(f)
    if not finite.all():
        bad = ~finite
        cols = [FEATURE_NAMES[j] for j in np.flatnonzero(bad.any(axis=0))]
        reasons.append(f"non-finite values in {', '.join(cols)} at samples {_ranges(bad.any(axis=1))}")
    g = np.where(finite, f, 0.0)
    subnormal = (g != 0) & (np.abs(g) < _TINY)
    dead = np.all((g == 0) | subnormal, axis=0) & finite.all(axis=0)
    if dead.any():
        names = [FEATURE_NAMES[j] for j in np.flatnonzero(dead)]
        reasons.append(f"dead channel(s): {', '.join(names)} zero or subnormal in all {f.shape[0]} samples")
    live_sub = subnormal & ~dead[None, :]
    if live_sub.any():
        cols = [FEATURE_NAMES[j] for j in np.flatnonzero(live_sub.any(axis=0))]
        reasons.append(f"subnormal (garbage) values in {', '.join(cols)}")
    out = finite & ((f < _LOW) | (f > _HIGH))
    for j in np.flatnonzero(out.any(axis=0)):
        name = FEATURE_NAMES[j]
        lo, hi = PLAUSIBLE_RANGES[name]
        col = f[out[:, j], j]
        worst = col[np.argmax(np.maximum(lo - col, col - hi))]
        reasons.append(f"{name} outside its plausible range [{lo:g}, {hi:g}] {FEATURE_UNITS[j]} in "
                       f"{int(out[:, j].sum())} samples (e.g. {worst:g})")
    return reasons


# ----------------------------------------------------------------------------------------------
# CSV reading


@dataclass
class _Block:
    first_line: int
    rows: list[list[float]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    last_index: int = -1
    last_line: int = 0


def _parse_row(line: str) -> tuple[list[float] | None, str | None]:
    parts = line.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        bad = next(p for p in parts if not _is_float(p))
        return None, f"non-numeric value {bad.strip()[:20]!r}"
    return values, None


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def load_csv_class(path: str | Path, label: int, class_name: str | None = None
                   ) -> tuple[list[Demonstration], list[LibraryIssue]]:
    """Read one class file of the paper's CSV format.

    Args:
        path: The ``.csv`` file.
        label: Class index given to its demonstrations.
        class_name: Class name (default: the file's stem).

    Returns:
        ``(demos, issues)``: the valid demonstrations (``index`` counts valid ones only) and the
        malformed blocks.

    Raises:
        LibraryError: If the file cannot be read.
    """
    p = Path(path)
    name = class_name or p.stem
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LibraryError(f"cannot read library file {str(p)!r}: {exc.strerror or exc}") from None
    blocks: list[_Block] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        values, problem = _parse_row(line)
        idx: float | None = values[0] if values else None
        starts = idx == 0.0 or not blocks
        if starts:
            blocks.append(_Block(first_line=lineno))
        blk = blocks[-1]
        blk.last_line = lineno
        if values is None:
            blk.problems.append(f"line {lineno}: {problem}")
            continue
        if len(values) != _N_COLS:
            blk.problems.append(f"line {lineno}: {len(values)} columns, expected {_N_COLS} "
                                f"(sample index + {len(FEATURE_NAMES)} features)")
            continue
        expected = blk.last_index + 1
        if idx != expected and not blk.problems:
            blk.problems.append(f"line {lineno}: sample index {values[0]:g} where {expected} was expected "
                                "(index column must count 0, 1, 2, ...)")
        if idx is not None and math.isfinite(idx) and float(idx).is_integer():
            blk.last_index = int(idx)
        else:
            blk.last_index = expected
        blk.rows.append(values[1:])
    demos: list[Demonstration] = []
    issues: list[LibraryIssue] = []
    typical = float(np.median([len(b.rows) for b in blocks])) if blocks else 0.0
    for b, blk in enumerate(blocks):
        where = f"lines {blk.first_line}-{blk.last_line}"
        reasons = list(blk.problems)
        if not reasons and len(blk.rows) < TRUNCATED_FRACTION * typical:
            reasons.append(f"truncated: {len(blk.rows)} samples where the file's blocks typically have "
                           f"{typical:g}")
        if not reasons:
            reasons = validate_block(np.asarray(blk.rows, dtype=np.float64).reshape(-1, len(FEATURE_NAMES)))
        if reasons:
            issues.append(LibraryIssue(name, b, f"{where}: " + "; ".join(reasons)))
            continue
        feats = np.asarray(blk.rows, dtype=np.float64)
        feats.setflags(write=False)
        demos.append(Demonstration(label, name, len(demos), feats, f"{p.name}#block {b}"))
    if not demos:
        issues.append(LibraryIssue(name, -1, f"{p.name} holds no valid demonstration"))
    return demos, issues


def _class_files(directory: Path) -> list[Path]:
    files = list(directory.glob("compound_*.csv"))
    if files:
        def key(p: Path) -> tuple[int, str]:
            m = re.fullmatch(r"compound_(\d+)", p.stem)
            return (int(m.group(1)) if m else 1 << 30, p.name)
        return sorted(files, key=key)
    return sorted(directory.glob("*.csv"))


def _load_csv_dir(directory: Path) -> MotionLibrary:
    files = _class_files(directory)
    if not files:
        raise LibraryError(f"library directory {str(directory)!r} holds no .csv class files")
    names: list[str] = []
    demos: list[Demonstration] = []
    issues: list[LibraryIssue] = []
    for label, f in enumerate(files):
        d, i = load_csv_class(f, label)
        names.append(f.stem)
        demos.extend(d)
        issues.extend(i)
    return MotionLibrary(names, demos, issues, str(directory))


# ----------------------------------------------------------------------------------------------
# npz


def save_library(lib: MotionLibrary, path: str | Path) -> None:
    """Write ``lib`` as a compact native ``.npz`` (no pickled objects).

    Args:
        lib: The library.
        path: Output file; ``.npz`` is appended by numpy if missing. Parent directories are created.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    feats = (np.concatenate([d.features for d in lib.demos]).astype(np.float64)
             if lib.demos else np.zeros((0, len(FEATURE_NAMES))))

    def strings(items: list[str]) -> np.ndarray:
        return np.array(items, dtype=np.str_) if items else np.zeros(0, dtype="<U1")

    np.savez_compressed(
        p,
        format_version=np.int64(NPZ_FORMAT),
        feature_names=strings(list(FEATURE_NAMES)),
        class_names=strings(list(lib.class_names)),
        features=feats,
        demo_label=np.array([d.label for d in lib.demos], dtype=np.int64),
        demo_index=np.array([d.index for d in lib.demos], dtype=np.int64),
        demo_length=np.array([d.n_samples for d in lib.demos], dtype=np.int64),
        demo_source=strings([d.source for d in lib.demos]),
        issue_class=strings([i.class_name for i in lib.issues]),
        issue_block=np.array([i.block for i in lib.issues], dtype=np.int64),
        issue_reason=strings([i.reason for i in lib.issues]),
        source=np.array(lib.source, dtype=np.str_),
    )


_NPZ_KEYS = ("format_version", "feature_names", "class_names", "features", "demo_label", "demo_index",
             "demo_length", "demo_source", "issue_class", "issue_block", "issue_reason", "source")


def _load_npz(path: Path) -> MotionLibrary:
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in _NPZ_KEYS if k not in z.files]
            if missing:
                raise LibraryError(f"library file {str(path)!r}: not a Foresight library npz "
                                   f"(missing {', '.join(missing)})")
            data = {k: z[k] for k in _NPZ_KEYS}
    except LibraryError:
        raise
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise LibraryError(f"library file {str(path)!r}: unreadable npz ({type(exc).__name__}: {exc})") from None
    where = f"library file {str(path)!r}"
    if int(data["format_version"]) != NPZ_FORMAT:
        raise LibraryError(f"{where}: format_version {int(data['format_version'])}, this build reads {NPZ_FORMAT}")
    if tuple(data["feature_names"].tolist()) != FEATURE_NAMES:
        raise LibraryError(f"{where}: feature_names differ from {', '.join(FEATURE_NAMES)}")
    names = [str(s) for s in data["class_names"].tolist()]
    feats = np.asarray(data["features"], dtype=np.float64)
    labels, indices, lengths = data["demo_label"], data["demo_index"], data["demo_length"]
    sources = [str(s) for s in data["demo_source"].tolist()]
    n = len(labels)
    if feats.ndim != 2 or feats.shape[1] != len(FEATURE_NAMES):
        raise LibraryError(f"{where}: features has shape {feats.shape}, expected (N, {len(FEATURE_NAMES)})")
    if not (len(indices) == len(lengths) == len(sources) == n):
        raise LibraryError(f"{where}: demo_label/demo_index/demo_length/demo_source lengths differ")
    if n and (lengths.min() < 1 or int(lengths.sum()) != feats.shape[0]):
        raise LibraryError(f"{where}: demo_length does not add up to the {feats.shape[0]} feature rows")
    if n and (labels.min() < 0 or labels.max() >= len(names)):
        raise LibraryError(f"{where}: demo_label outside 0..{len(names) - 1}")
    issues = [LibraryIssue(str(c), int(b), str(r)) for c, b, r in
              zip(data["issue_class"].tolist(), data["issue_block"].tolist(), data["issue_reason"].tolist(),
                  strict=False)]
    demos: list[Demonstration] = []
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    for k in range(n):
        f = feats[offsets[k]:offsets[k + 1]].copy()
        reasons = validate_block(f)
        label = int(labels[k])
        if reasons:  # a hand-edited npz gets the same scrutiny as a CSV
            issues.append(LibraryIssue(names[label], k, f"npz demonstration {k}: " + "; ".join(reasons)))
            continue
        f.setflags(write=False)
        demos.append(Demonstration(label, names[label], int(indices[k]), f, sources[k]))
    demos.sort(key=lambda d: (d.label, d.index))
    return MotionLibrary(names, demos, issues, str(data["source"]) or str(path))


# ----------------------------------------------------------------------------------------------
# public entry points


def load_library(path: str | Path) -> MotionLibrary:
    """Read a library: a directory of ``compound_*.csv`` (paper format) or an ``.npz`` from :func:`save_library`.

    Malformed demonstrations are reported in ``issues`` and left out of ``demos``.

    Args:
        path: Directory or ``.npz`` file.

    Returns:
        The library.

    Raises:
        LibraryError: If the path does not exist, holds no class files, or is not a valid npz.
    """
    p = Path(path).expanduser()
    if p.is_dir():
        return _load_csv_dir(p)
    if p.is_file():
        if p.suffix == ".npz":
            return _load_npz(p)
        if p.suffix == ".csv":
            raise LibraryError(f"library {str(p)!r} is a single CSV file; pass the directory holding the "
                               "class files")
        raise LibraryError(f"library {str(p)!r} is neither a directory of CSV files nor a .npz file")
    raise LibraryError(f"library {str(p)!r} not found")


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
        LibraryError: If ``n_per_class`` is negative or leaves a class without training data.
    """
    if n_per_class < 0:
        raise LibraryError(f"heldout: n_per_class must be >= 0, got {n_per_class}")
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
