"""The paper's CSV format of a motion library: reading (with its format rules) and writing.

A directory of ``compound_<m>.csv``, one file per class (see ``../shared/data/paper-library/README.md``):
comma-separated, no header, one posture per row, demonstrations one after another; column 0 is the
sample index within its demonstration (it returns to 0 where a new demonstration starts), columns
1..F are the features. The column count declares F: 13 columns are the paper's 12 features; any
other count C gives C - 1 features named ``feature_1 .. feature_<C-1>`` without a mapping. The count
is the one most of the class files have (each file by its most common line length); a file with
another count is left out with one issue line saying how many lines of which counts it has.

On top of :func:`shared.library.validation.validate_block`, a block (demonstration) must have the
library's column count of numeric values in every row, an index column counting 0, 1, 2, ... without
gaps, must not be much shorter than its file's other blocks (:data:`TRUNCATED_FRACTION`) and must not
repeat an earlier block's values (a file joined to itself). A block that breaks a rule is left out and
reported as a :class:`LibraryIssue` (class, block index, reason). A value is a plain number (``1_0`` is
not 10); beside ``compound_<digits>.csv`` files no other .csv is a class; a kept last block shorter than
its file's others, all of one length, is said (the file may have been cut); a file over
:data:`MAX_CLASS_FILE_BYTES` is refused. Writing: :mod:`~shared.library.csv_write`.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shared.feature_sets import generic_names

from .csv_write import write_csv_dir
from .motions import FEATURE_NAMES, NO_VALID_DEMONSTRATION, Demonstration, LibraryError, LibraryIssue, MotionLibrary
from .validation import line_ranges, validate_block

__all__ = ["MAX_CLASS_FILE_BYTES", "TRUNCATED_FRACTION", "load_csv_class", "load_csv_dir", "write_csv_dir"]

TRUNCATED_FRACTION = 0.5
"""A block shorter than this fraction of its file's median block length is reported as truncated."""

MAX_CLASS_FILE_BYTES = 200_000_000
"""Largest class file read: parsing holds about 9 times a file's size in memory (the paper's are 0.3 MB each)."""

_PAPER_COLS = 1 + len(FEATURE_NAMES)


@dataclass
class _Block:
    first_line: int
    rows: list[list[float]] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)  # the file line of each row
    problems: list[str] = field(default_factory=list)
    columns: dict[int, list[int]] = field(default_factory=dict)  # wrong column count -> its line numbers
    text: list[tuple[int, str]] = field(default_factory=list)  # (line, problem) of non-numeric rows
    nonfinite: list[tuple[int, str]] = field(default_factory=list)  # (line, problem) of rows with nan/inf
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
            elif kind in ("text", "nonfinite"):
                rows = self.text if kind == "text" else self.nonfinite
                what = "non-numeric" if kind == "text" else "non-finite"
                (line, problem), n = rows[0], len(rows)
                out.append(f"line {line}: {problem}" if n == 1 else
                           f"{n} lines with {what} values (lines {line_ranges(t[0] for t in rows)}; "
                           f"line {line}: {problem})")
            else:
                for count, lines in self.columns.items():
                    what = (f"line {lines[0]}: {count} columns" if len(lines) == 1 else
                            f"{len(lines)} lines (lines {line_ranges(lines)}) have {count} columns")
                    out.append(f"{what}, expected {n_cols} (sample index + {n_cols - 1} features)")
        return out


def _number(text: str) -> float:
    """A field's value; ``float()`` but for its digit separators (``1_0`` is 10 to it, a typo in a CSV)."""
    if "_" in text:
        raise ValueError(f"not a number: {text!r}")
    return float(text)


def _parse_row(line: str) -> tuple[list[float] | None, str | None]:
    parts = line.split(",")
    try:
        values = [_number(p) for p in parts]
    except ValueError:
        bad = next(p for p in parts if not _is_float(p))
        return None, f"non-numeric value {bad.strip()[:20]!r}"
    return values, None


def _is_float(text: str) -> bool:
    try:
        _number(text)
    except ValueError:
        return False
    return True


def _read_lines(p: Path) -> list[tuple[int, str]]:
    """The non-blank lines of a class file with their 1-based line numbers."""
    try:
        size = p.stat().st_size
        if size > MAX_CLASS_FILE_BYTES:
            raise LibraryError(f"library file {str(p)!r}: {size / 1e6:.0f} MB, over the "
                               f"{MAX_CLASS_FILE_BYTES / 1e6:.0f} MB a class file may have (reading holds about 9 "
                               "times its size in memory)")
        text = p.read_text(encoding="utf-8-sig", errors="replace")  # a byte-order mark is not part of line 1
    except OSError as exc:
        raise LibraryError(f"cannot read library file {str(p)!r}: {exc.strerror or exc}") from None
    # a row of empty fields (",,,,", a spreadsheet's export) is as blank as an empty line: it was taken for a row of
    # the demonstration before it, and cost that demonstration
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if line.replace(",", "").strip()]
    trailing = sum(line.rstrip().endswith(",") for _, line in lines)
    if lines and trailing >= 0.9 * len(lines):  # a trailing comma on (nearly) every line: no empty 14th column
        lines = [(n, line.rstrip()[:-1] if line.rstrip().endswith(",") else line) for n, line in lines]
    return lines


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


def _numbered_header(lines: list[tuple[int, str]]) -> bool:
    """Whether the first line is columns numbered 0, 1, 2, ... (pandas' default header) before a block's first row."""
    fields = lines[0][1].split(",")
    if len(lines) < 2 or not all(_is_float(f) for f in fields) or len(fields) < 3:
        return False
    second = lines[1][1].split(",", 1)[0]
    return [_number(f) for f in fields] == [float(i) for i in range(len(fields))] and _is_float(second) \
        and _number(second) == 0.0


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
    if lines and (not any(_is_float(f) for f in lines[0][1].split(",")) or _numbered_header(lines)):
        header = lines[0][1].strip()  # column names: not a demonstration, and neither is the same line again
        lines = [(n, line) for n, line in lines[1:] if line.strip() != header]  # (two files joined with cat)
    for lineno, line in lines:
        values, problem = _parse_row(line)
        # a row that does not parse still starts a demonstration when its sample index is 0: else the row and
        # the demonstration after it would be merged into the one before
        first = line.split(",", 1)[0]
        idx: float | None = values[0] if values else (_number(first) if _is_float(first) else None)
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
        bad = [j for j, v in enumerate(values) if not math.isfinite(v)]
        if bad:
            j = bad[0]
            name_j = "sample index" if j == 0 else feature_names[j - 1]
            more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
            blk.order["nonfinite"] = None
            blk.nonfinite.append((lineno, f"{values[j]} in column {j + 1} ({name_j}){more}"))
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
        blk.lines.append(lineno)
    demos: list[Demonstration] = []
    issues: list[LibraryIssue] = []
    first_of: dict[bytes, int] = {}  # a demonstration's values -> the block they were first read from
    typical = float(np.median([len(b.rows) for b in blocks])) if blocks else 0.0
    for b, blk in enumerate(blocks):
        where = f"lines {blk.first_line}-{blk.last_line}"
        reasons = blk.reasons(n_cols)
        if not reasons and len(blk.rows) < TRUNCATED_FRACTION * typical:
            reasons.append(f"truncated: {len(blk.rows)} samples where the file's blocks typically have "
                           f"{typical:g}")
        if not reasons:
            reasons = validate_block(np.asarray(blk.rows, dtype=np.float64).reshape(-1, n_cols - 1), feature_names,
                                     blk.lines)
        if reasons:
            issues.append(LibraryIssue(name, b, f"{where}: " + "; ".join(reasons)))
            continue
        feats = np.asarray(blk.rows, dtype=np.float64)
        twin = first_of.setdefault(feats.tobytes(), b)
        if twin != b:  # a file joined to itself: held out, a demonstration would be recognised by its own copy
            issues.append(LibraryIssue(name, b, f"{where}: the same values as block {twin} (lines "
                                       f"{blocks[twin].first_line}-{blocks[twin].last_line}): a repeated "
                                       "demonstration, left out"))
            continue
        feats.setflags(write=False)
        demos.append(Demonstration(label, name, len(demos), feats, f"{p.name}#block {b}"))
    if not demos:
        issues.append(LibraryIssue(name, -1, f"{p.name} {NO_VALID_DEMONSTRATION}"))
    elif demos[-1].source == f"{p.name}#block {len(blocks) - 1}":
        issues.extend(_cut_short(p, name, blocks[-1], demos))
    return demos, issues


def _cut_short(p: Path, name: str, last: _Block, demos: list[Demonstration]) -> list[LibraryIssue]:
    """A note on a kept last demonstration shorter than the file's others, all of one length: a file cut short.

    Cut at a line end, the rest of the file is valid; the last block passes when it keeps
    :data:`TRUNCATED_FRACTION` of its samples, and a variable-length library has shorter ones of its own.
    """
    lengths = {d.n_samples for d in demos[:-1]}
    if len(demos) < 3 or len(lengths) != 1 or demos[-1].n_samples >= min(lengths):
        return []
    return [LibraryIssue(name, -1, f"{p.name}: its last demonstration (lines {last.first_line}-{last.last_line}) "
                         f"has {demos[-1].n_samples} samples where its other {len(demos) - 1} all have "
                         f"{min(lengths)}: the file may have been cut short (kept)")]


def _class_number(p: Path) -> int | None:
    """The number of a ``compound_<m>.csv`` class file (None: not numbered so)."""
    m = re.fullmatch(r"compound_(\d+)", p.stem)
    return int(m.group(1)) if m else None


def _class_files(directory: Path) -> list[Path]:
    """The class files: ``compound_<digits>.csv`` where there are any, else every .csv.

    ``compound_3 (copy).csv`` or ``compound_2.bak.csv`` beside numbered files are no classes (they split a
    class's posterior with its copy); :func:`_unread` names them.
    """
    files = list(directory.glob("compound_*.csv"))
    numbered = {f: n for f in files if (n := _class_number(f)) is not None}
    if numbered:
        return sorted(numbered, key=lambda f: (numbered[f], f.name))
    return sorted(files or directory.glob("*.csv"))


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


def load_csv_dir(directory: Path) -> MotionLibrary:
    """Read a directory of class files (one class per ``compound_<m>.csv``, in their numeric order).

    Raises:
        LibraryError: If it holds no class files or they disagree on the column count.
    """
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
    return MotionLibrary(names, demos, issues + _unread(directory, files), str(directory), _feature_names_for(n_cols))


def _unread(directory: Path, files: list[Path]) -> list[LibraryIssue]:
    """What a directory of ``compound_<m>.csv`` does not read, said: its other .csv files, and numbers missing.

    Both passed without a word: ``reach_a.csv`` beside ``compound_1.csv`` was not read, and without
    ``compound_1.csv`` the classes are numbered in their files' order, so class 1 is ``compound_2``.
    """
    numbers = {f: n for f in files if (n := _class_number(f)) is not None}
    if not numbers:
        return []
    out = [LibraryIssue(f.stem, -1, f"{f.name} not read: beside compound_<m>.csv files only those are the "
                                    "library's classes")
           for f in sorted(set(directory.glob("*.csv")) - set(files))]
    by_number: dict[int, list[Path]] = {}
    for f, n in numbers.items():
        by_number.setdefault(n, []).append(f)
    for n, same in sorted(by_number.items()):
        if len(same) > 1:  # compound_0.csv and compound_00.csv: both read, as two classes
            out.append(LibraryIssue(same[1].stem, -1, f"{' and '.join(f.name for f in same)} have the same number "
                                    f"{n}: both read, as classes {', '.join(str(files.index(f)) for f in same)}"))
    missing = sorted(set(range(max(by_number) + 1)) - set(by_number))
    if missing:
        shown = ", ".join(f"compound_{m}.csv" for m in missing[:4]) + (" ..." if len(missing) > 4 else "")
        after = next(f for f in files if numbers.get(f, -1) > missing[0])
        out.append(LibraryIssue(f"compound_{missing[0]}", -1, f"{shown} missing: the classes are numbered in their "
                                f"files' order (class {files.index(after)} is {after.stem})"))
    return out
