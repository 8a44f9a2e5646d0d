"""Human-motion libraries: the paper's CSV format, a compact native npz format, and validation.

A *library* holds M motion classes, each with several *demonstrations* (recorded motions of T
samples of F joint features). The library declares its features (``MotionLibrary.feature_names``):
the paper's 12 (:data:`FEATURE_NAMES`, the HERAKLES human model's joints) or any other fixed set
(``shared.feature_sets``: recognition works on any set, the occupancy needs a mapping to the human
model).

Paper format (a directory of ``compound_<m>.csv``, one file per class, see
``../shared/data/paper-library/README.md``): comma-separated, no header, one posture per row,
demonstrations one after another; column 0 is the sample index within its demonstration (it
returns to 0 where a new demonstration starts), columns 1..F are the features. The column count
declares F: 13 columns are the paper's 12 features; any other count C gives C - 1 features named
``feature_1 .. feature_<C-1>`` without a mapping. The count is the one most of the class files have
(each file by its most common line length); a file with another count is left out with one issue
line saying how many lines of which counts it has.

Every demonstration (a *block* of rows) is validated by general rules before it is used:
the row has the library's column count of numeric values, every value is finite and not
subnormal, the index column counts 0, 1, 2, ... without gaps, the block has at least
:data:`MIN_SAMPLES` samples and is not much shorter than its file's other blocks
(:data:`TRUNCATED_FRACTION`), no feature is identically zero over the block (a dead channel) and,
for a feature set with a mapping, every feature stays within its plausible range
(:data:`PLAUSIBLE_RANGES` for the paper's). A block that breaks a rule is left out and reported as
a :class:`LibraryIssue` (class, block index, reason); it never reaches training.

Native format (written by :func:`save_library`): one ``.npz`` without pickles holding the
concatenated features, per-demonstration labels, lengths, indices and sources, the class names
and the issues found when the library was read.
"""

from __future__ import annotations

import math
import re
import zipfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shared.feature_sets import (
    HERAKLES_NAMES,
    HERAKLES_RANGES,
    HERAKLES_UNITS,
    FeatureMapping,
    generic_names,
    mapping_for,
)

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

FEATURE_NAMES: tuple[str, ...] = HERAKLES_NAMES
"""The paper's 12 features of a posture, in its (and its CSV's) order (``shared.feature_sets``)."""

FEATURE_UNITS: tuple[str, ...] = HERAKLES_UNITS

PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = HERAKLES_RANGES
"""Per-feature ``(low, high)`` bounds of a plausible human posture (recorder frame)."""

MIN_SAMPLES = 10
"""Shortest demonstration accepted (samples)."""

TRUNCATED_FRACTION = 0.5
"""A block shorter than this fraction of its file's median block length is reported as truncated."""

NPZ_FORMAT = 1
"""Version of the native npz layout written by :func:`save_library`."""

_PAPER_COLS = 1 + len(FEATURE_NAMES)
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


@dataclass
class MotionLibrary:
    """Demonstrations of M classes plus the issues found while reading them.

    Attributes:
        class_names: M class names; ``class_names[label]``.
        demos: Valid demonstrations, ordered by (label, index).
        issues: Malformed demonstrations that were left out.
        source: Path the library was read from (or a description for generated ones).
        feature_names: The F features of every demonstration, in column order (default: the paper's 12).
    """

    class_names: list[str]
    demos: list[Demonstration]
    issues: list[LibraryIssue] = field(default_factory=list)
    source: str = ""
    feature_names: tuple[str, ...] = FEATURE_NAMES

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


# ----------------------------------------------------------------------------------------------
# validation


def _ranges(mask: np.ndarray) -> str:
    """``[F, F, T, T, F, T]`` -> ``"2-3, 5"`` (0-based positions of True, compressed)."""
    return _line_ranges(np.flatnonzero(mask).tolist())


def validate_block(features: np.ndarray, feature_names: tuple[str, ...] = FEATURE_NAMES) -> list[str]:
    """Check one demonstration's features against the library rules.

    Args:
        features: ``(T, F)`` feature rows of one block.
        feature_names: The F feature names; the plausible ranges are checked where they have a mapping.

    Returns:
        Reasons the block is malformed (empty when it is valid). Sample positions are 0-based.
    """
    names = tuple(feature_names)
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[1] != len(names):
        return [f"has shape {f.shape}, expected (T, {len(names)})"]
    reasons: list[str] = []
    if f.shape[0] < MIN_SAMPLES:
        reasons.append(f"has {f.shape[0]} samples, fewer than the minimum {MIN_SAMPLES}")
    finite = np.isfinite(f)
    if not finite.all():
        bad = ~finite
        cols = [names[j] for j in np.flatnonzero(bad.any(axis=0))]
        reasons.append(f"non-finite values in {', '.join(cols)} at samples {_ranges(bad.any(axis=1))}")
    g = np.where(finite, f, 0.0)
    subnormal = (g != 0) & (np.abs(g) < _TINY)
    dead = np.all((g == 0) | subnormal, axis=0) & finite.all(axis=0)
    if dead.any():
        reasons.append(f"dead channel(s): {', '.join(names[j] for j in np.flatnonzero(dead))} zero or subnormal "
                       f"in all {f.shape[0]} samples")
    live_sub = subnormal & ~dead[None, :]
    if live_sub.any():
        cols = [names[j] for j in np.flatnonzero(live_sub.any(axis=0))]
        reasons.append(f"subnormal (garbage) values in {', '.join(cols)}")
    mapping = mapping_for(names)
    if mapping is None:  # no plausible ranges known for an unmapped feature set
        return reasons
    low = np.array([mapping.plausible_ranges[n][0] for n in names])
    high = np.array([mapping.plausible_ranges[n][1] for n in names])
    out = finite & ((f < low) | (f > high))
    for j in np.flatnonzero(out.any(axis=0)):
        name = names[j]
        lo, hi = mapping.plausible_ranges[name]
        col = f[out[:, j], j]
        worst = col[np.argmax(np.maximum(lo - col, col - hi))]
        reasons.append(f"{name} outside its plausible range [{lo:g}, {hi:g}] {mapping.units[j]} in "
                       f"{int(out[:, j].sum())} samples (e.g. {worst:g})")
    return reasons


# ----------------------------------------------------------------------------------------------
# CSV reading


@dataclass
class _Block:
    first_line: int
    rows: list[list[float]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    columns: dict[int, list[int]] = field(default_factory=dict)  # wrong column count -> its line numbers
    text: list[tuple[int, str]] = field(default_factory=list)  # (line, problem) of non-numeric rows
    order: dict[str, None] = field(default_factory=dict)  # kinds of problem in order of first occurrence
    last_index: int = -1
    last_line: int = 0

    @property
    def bad(self) -> bool:
        return bool(self.order)

    def reasons(self, n_cols: int) -> list[str]:
        """The block's problems, one entry per kind (never one per line)."""
        out: list[str] = []
        for kind in self.order:
            if kind == "index":
                out.extend(self.problems)
            elif kind == "text":
                (line, problem), n = self.text[0], len(self.text)
                out.append(f"line {line}: {problem}" if n == 1 else
                           f"{n} lines with non-numeric values (lines {_line_ranges(t[0] for t in self.text)}; "
                           f"line {line}: {problem})")
            else:
                for count, lines in self.columns.items():
                    what = (f"line {lines[0]}: {count} columns" if len(lines) == 1 else
                            f"{len(lines)} lines (lines {_line_ranges(lines)}) have {count} columns")
                    out.append(f"{what}, expected {n_cols} (sample index + {n_cols - 1} features)")
        return out


def _line_ranges(lines) -> str:
    """Line numbers ``[5, 6, 7, 9]`` -> ``"5-7, 9"`` (at most four ranges, then ``...``)."""
    parts: list[str] = []
    start = prev = None
    for n in lines:
        if start is None:
            start = prev = n
        elif n == prev + 1:
            prev = n
        else:
            parts.append(f"{start}" if start == prev else f"{start}-{prev}")
            start = prev = n
    if start is not None:
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
    return ", ".join(parts[:4] + (["..."] if len(parts) > 4 else []))


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


def _read_lines(p: Path) -> list[tuple[int, str]]:
    """The non-blank lines of a class file with their 1-based line numbers."""
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LibraryError(f"cannot read library file {str(p)!r}: {exc.strerror or exc}") from None
    return [(n, line) for n, line in enumerate(text.splitlines(), start=1) if line.strip()]


def _column_counts(lines: list[tuple[int, str]]) -> Counter[int]:
    """How many lines have each column count (comma-separated fields)."""
    return Counter(line.count(",") + 1 for _, line in lines)


def _count_summary(counts: Counter[int]) -> str:
    """How many lines of which column counts.

    ``{17: 2500}`` -> ``"2500 lines of 17 columns"``; ``{17: 2400, 13: 100}`` ->
    ``"2500 lines (2400 of 17 columns, 100 of 13)"``.
    """
    ranked = counts.most_common()
    if len(ranked) == 1:
        return f"{ranked[0][1]} lines of {ranked[0][0]} columns"
    parts = [f"{n} of {c} columns" if i == 0 else f"{n} of {c}" for i, (c, n) in enumerate(ranked)]
    return f"{sum(counts.values())} lines ({', '.join(parts)})"


def _feature_names_for(n_cols: int) -> tuple[str, ...]:
    """Feature names a CSV of ``n_cols`` columns declares: the paper's for 13, ``feature_1..`` otherwise."""
    return FEATURE_NAMES if n_cols == _PAPER_COLS else generic_names(n_cols - 1)


def load_csv_class(path: str | Path, label: int, class_name: str | None = None, n_columns: int | None = None
                   ) -> tuple[list[Demonstration], list[LibraryIssue]]:
    """Read one class file of the paper's CSV format.

    Args:
        path: The ``.csv`` file.
        label: Class index given to its demonstrations.
        class_name: Class name (default: the file's stem).
        n_columns: Columns every row must have (sample index + F features); default: the file's most
            common line length. 13 columns are the paper's 12 features, others ``feature_1 ..``.

    Returns:
        ``(demos, issues)``: the valid demonstrations (``index`` counts valid ones only) and the
        malformed blocks.

    Raises:
        LibraryError: If the file cannot be read.
    """
    p = Path(path)
    lines = _read_lines(p)
    if n_columns is None:
        counts = _column_counts(lines)
        n_columns = counts.most_common(1)[0][0] if counts else _PAPER_COLS
    return _parse_class(p, lines, label, class_name or p.stem, n_columns)


def _parse_class(p: Path, lines: list[tuple[int, str]], label: int, name: str, n_cols: int
                 ) -> tuple[list[Demonstration], list[LibraryIssue]]:
    feature_names = _feature_names_for(n_cols)
    blocks: list[_Block] = []
    for lineno, line in lines:
        values, problem = _parse_row(line)
        idx: float | None = values[0] if values else None
        starts = idx == 0.0 or not blocks
        if starts:
            blocks.append(_Block(first_line=lineno))
        blk = blocks[-1]
        blk.last_line = lineno
        if values is None:
            blk.order["text"] = None
            blk.text.append((lineno, str(problem)))
            continue
        if len(values) != n_cols:
            blk.order["columns"] = None
            blk.columns.setdefault(len(values), []).append(lineno)
            continue
        expected = blk.last_index + 1
        if idx != expected and not blk.bad:
            blk.order["index"] = None
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
        reasons = blk.reasons(n_cols)
        if not reasons and len(blk.rows) < TRUNCATED_FRACTION * typical:
            reasons.append(f"truncated: {len(blk.rows)} samples where the file's blocks typically have "
                           f"{typical:g}")
        if not reasons:
            reasons = validate_block(np.asarray(blk.rows, dtype=np.float64).reshape(-1, n_cols - 1), feature_names)
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


def _library_columns(directory: Path, files: list[Path], counts: list[Counter[int]]) -> int:
    """The column count most class files have (each file voting with its most common line length).

    Raises:
        LibraryError: If no count has more files than every other (one line naming each file's counts).
    """
    votes = Counter(c.most_common(1)[0][0] for c in counts if c)
    ranked = votes.most_common()
    if not ranked:
        return _PAPER_COLS
    if len(ranked) > 1 and ranked[0][1] == ranked[1][1]:
        per_file = "; ".join(f"{f.name}: {_count_summary(c)}" for f, c in zip(files, counts, strict=True) if c)
        raise LibraryError(f"library {str(directory)!r}: its class files disagree on the column count and no "
                           f"count has a majority ({per_file}); every class file needs the same columns (sample "
                           "index + the same features)")
    n_cols = ranked[0][0]
    if n_cols < 2:
        raise LibraryError(f"library {str(directory)!r}: its class files have {n_cols} column; the format is a "
                           "sample index followed by the features, comma-separated")
    return n_cols


def _load_csv_dir(directory: Path) -> MotionLibrary:
    files = _class_files(directory)
    if not files:
        raise LibraryError(f"library directory {str(directory)!r} holds no .csv class files")
    lines = [_read_lines(f) for f in files]
    counts = [_column_counts(ls) for ls in lines]
    n_cols = _library_columns(directory, files, counts)
    names: list[str] = []
    demos: list[Demonstration] = []
    issues: list[LibraryIssue] = []
    for label, (f, ls, c) in enumerate(zip(files, lines, counts, strict=True)):
        names.append(f.stem)
        if c and c.most_common(1)[0][0] != n_cols:  # a file of another shape: one line, not one per sample
            issues.append(LibraryIssue(f.stem, -1, f"{f.name} has {_count_summary(c)} where the library's other "
                                       f"class files have {n_cols} columns (sample index + {n_cols - 1} features); "
                                       "no demonstration read"))
            continue
        d, i = _parse_class(f, ls, label, f.stem, n_cols)
        demos.extend(d)
        issues.extend(i)
    return MotionLibrary(names, demos, issues, str(directory), _feature_names_for(n_cols))


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
             if lib.demos else np.zeros((0, lib.n_features)))

    def strings(items: list[str]) -> np.ndarray:
        return np.array(items, dtype=np.str_) if items else np.zeros(0, dtype="<U1")

    np.savez_compressed(
        p,
        format_version=np.int64(NPZ_FORMAT),
        feature_names=strings(list(lib.feature_names)),
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
    feature_names = tuple(str(s) for s in data["feature_names"].tolist())
    if not feature_names or len(set(feature_names)) != len(feature_names):
        raise LibraryError(f"{where}: feature_names must be unique names of at least one feature, got "
                           f"{len(feature_names)} names ({len(set(feature_names))} distinct)")
    names = [str(s) for s in data["class_names"].tolist()]
    feats = np.asarray(data["features"], dtype=np.float64)
    labels, indices, lengths = data["demo_label"], data["demo_index"], data["demo_length"]
    sources = [str(s) for s in data["demo_source"].tolist()]
    n = len(labels)
    if feats.ndim != 2 or feats.shape[1] != len(feature_names):
        raise LibraryError(f"{where}: features has shape {feats.shape}, expected (N, {len(feature_names)}) for its "
                           f"{len(feature_names)} feature_names")
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
        reasons = validate_block(f, feature_names)
        label = int(labels[k])
        if reasons:  # a hand-edited npz gets the same scrutiny as a CSV
            issues.append(LibraryIssue(names[label], k, f"npz demonstration {k}: " + "; ".join(reasons)))
            continue
        f.setflags(write=False)
        demos.append(Demonstration(label, names[label], int(indices[k]), f, sources[k]))
    demos.sort(key=lambda d: (d.label, d.index))
    return MotionLibrary(names, demos, issues, str(data["source"]) or str(path), feature_names)


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
