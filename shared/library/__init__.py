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

Modules: :mod:`~shared.library.motions` (the library's types, held-out splits),
:mod:`~shared.library.validation` (the rules every demonstration passes),
:mod:`~shared.library.paper_csv` (the paper's CSV format, read; :mod:`~shared.library.csv_write` writes it),
:mod:`~shared.library.npz` (the native format), :mod:`~shared.library.report` (what reading dropped,
one line per file); :func:`load_library` (here) reads either and says what it dropped.
"""

from __future__ import annotations

from pathlib import Path

from shared.data_files import relative_to_cwd
from shared.protocol.limits import MAX_CLASSES, MAX_STRING_CHARS

from .motions import (
    FEATURE_NAMES,
    FEATURE_UNITS,
    PLAUSIBLE_RANGES,
    Demonstration,
    LibraryError,
    LibraryIssue,
    MotionLibrary,
    heldout_split,
)
from .npz import NPZ_FORMAT, load_npz, save_library
from .paper_csv import TRUNCATED_FRACTION, load_csv_class, load_csv_dir, write_csv_dir
from .report import drop_lines, report_drops
from .validation import MIN_SAMPLES, validate_block

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
    "write_csv_dir",
    "heldout_split",
    "drop_lines",
    "report_drops",
    "check_wire_limits",
]


def load_library(path: str | Path, report: bool = True) -> MotionLibrary:
    """Read a library: a directory of ``compound_*.csv`` (paper format) or an ``.npz`` from :func:`save_library`.

    Malformed demonstrations are reported in ``issues`` and left out of ``demos``; with ``report``
    what was dropped is also logged, one WARNING line per file (:func:`report_drops`).

    Args:
        path: Directory or ``.npz`` file.
        report: Log the dropped demonstrations (off for tools that print the issues themselves).

    Returns:
        The library.

    Raises:
        LibraryError: If the path is empty (it would read the current directory), does not exist, holds no
            class files, or is not a valid npz.
    """
    if not str(path).strip():
        raise LibraryError("library path: empty (give a directory of compound_*.csv or a .npz)")
    lib = _read(Path(path).expanduser())
    check_wire_limits(lib, path)
    if report:
        report_drops(lib)
    return lib


def check_wire_limits(lib: MotionLibrary, path: str | Path) -> None:
    """Refuse a library whose classes the predictor could not publish (docs/protocol.md's limits).

    Every read checks it; a command that writes a library checks it first, so that it never writes one that no
    command can read (``foresight library generate`` with a goal named "" did).

    Raises:
        LibraryError: Too many classes, or a class name of 0 or too many characters.
    """
    if lib.n_classes > MAX_CLASSES:
        raise LibraryError(f"library {str(path)!r}: {lib.n_classes} classes, over the wire's limit of {MAX_CLASSES} "
                           "(a ClassPosterior carries one probability per class)")
    for name in lib.class_names:
        if not name or len(name) > MAX_STRING_CHARS:
            raise LibraryError(f"library {str(path)!r}: class name {name[:40]!r}{'...' if len(name) > 40 else ''} "
                               f"has {len(name)} characters; class names are sent with every posterior and must "
                               f"have 1 to {MAX_STRING_CHARS}")


def _read(p: Path) -> MotionLibrary:
    if p.is_dir():
        return load_csv_dir(p)
    if p.is_file():
        if p.suffix == ".npz":
            return load_npz(p)
        if p.suffix == ".csv":
            raise LibraryError(f"library {str(p)!r} is a single CSV file; pass the directory holding the "
                               "class files")
        raise LibraryError(f"library {str(p)!r} is neither a directory of CSV files nor a .npz file")
    raise LibraryError(f"library {str(p)!r} not found{relative_to_cwd(p)}")
