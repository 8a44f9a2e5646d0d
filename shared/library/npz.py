"""The native format of a motion library: one compact ``.npz`` without pickles.

It holds the concatenated features, per-demonstration labels, lengths, indices and sources, the
class names, the feature names and the issues found when the library was read
(:data:`NPZ_FORMAT` is the layout's version). A stored demonstration is validated again on reading.
The library read names the ``.npz`` as its ``source``; the path it was converted from is its ``origin``.
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from shared.atomic_file import atomic_write
from shared.npz_reading import NPZ_LOCK

from .motions import Demonstration, LibraryError, LibraryIssue, MotionLibrary
from .validation import validate_block

__all__ = ["NPZ_FORMAT", "save_library", "load_npz"]

NPZ_FORMAT = 1
"""Version of the native npz layout written by :func:`save_library`."""


def save_library(lib: MotionLibrary, path: str | Path) -> None:
    """Write ``lib`` as a compact native ``.npz`` (no pickled objects).

    Args:
        lib: The library.
        path: Output file; ``.npz`` is appended if missing. Parent directories are created. Written whole
            (a temporary file renamed): an existing library is replaced only by a complete one.
    """
    p = Path(path)
    if p.suffix != ".npz":
        p = p.with_name(p.name + ".npz")
    feats = (np.concatenate([d.features for d in lib.demos]).astype(np.float64)
             if lib.demos else np.zeros((0, lib.n_features)))

    def strings(items: list[str]) -> np.ndarray:
        return np.array(items, dtype=np.str_) if items else np.zeros(0, dtype="<U1")

    with atomic_write(p) as f:
        np.savez_compressed(
            f,
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


def _starts(head: bytes) -> str:
    return "; the file is empty" if not head else f"; it starts with {head!r}"


def load_npz(path: Path) -> MotionLibrary:
    """Read a library written by :func:`save_library`.

    Raises:
        LibraryError: If the file is unreadable, not a Foresight library npz, or of another format version.
    """
    try:
        with open(path, "rb") as f:
            head = f.read(4)
        if head not in (b"PK\x03\x04", b"PK\x05\x06") and not head.startswith(b"\x93NUM"):
            raise LibraryError(f"library file {str(path)!r}: not an npz archive (a zip file){_starts(head)}")
        with NPZ_LOCK:
            loaded = np.load(path, allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):  # one .npy array under an .npz name
                raise LibraryError(f"library file {str(path)!r}: one array, not a Foresight library npz")
            with loaded as z:
                missing = [k for k in _NPZ_KEYS if k not in z.files]
                if missing and "format" in z.files and z["format"].ndim == 0:  # another Foresight file: say which
                    raise LibraryError(f"library file {str(path)!r}: a {str(z['format'])!r} file, not a motion "
                                       "library (its demonstrations)")
                if missing:
                    raise LibraryError(f"library file {str(path)!r}: not a Foresight library npz "
                                       f"(missing {', '.join(missing)})")
                data = {k: z[k] for k in _NPZ_KEYS}
    except LibraryError:
        raise
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:  # zlib: damaged data
        raise LibraryError(f"library file {str(path)!r}: unreadable npz ({type(exc).__name__}: {exc})") from None
    where = f"library file {str(path)!r}"
    try:
        return _library(path, data, where)
    except (TypeError, ValueError, IndexError, OverflowError) as exc:  # a field of the wrong kind or dimensions
        if isinstance(exc, LibraryError):
            raise
        raise LibraryError(f"{where}: inconsistent ({type(exc).__name__}: {exc})") from None


def _library(path: Path, data: dict[str, np.ndarray], where: str) -> MotionLibrary:
    """The library in ``data`` (the npz's arrays); raises LibraryError or, on an ill-kinded field, a ValueError."""
    for key in ("feature_names", "class_names", "demo_label", "demo_index", "demo_length", "demo_source",
                "issue_class", "issue_block", "issue_reason"):
        if data[key].ndim != 1:
            raise LibraryError(f"{where}: {key} must be a list (1-d), got {data[key].ndim}-d")
    for key in ("demo_label", "demo_index", "demo_length", "issue_block"):
        if data[key].size and data[key].dtype.kind not in "iu":
            raise LibraryError(f"{where}: {key} must hold integers, got {data[key].dtype}")
    version = data["format_version"]
    if version.ndim != 0:  # [1] said "format_version [1], this build reads 1"
        raise LibraryError(f"{where}: format_version must be a scalar, got shape {version.shape}")
    if version.dtype.kind not in "iu":
        raise LibraryError(f"{where}: format_version must be an integer, got {version.dtype} {version.tolist()!r}")
    if int(version) != NPZ_FORMAT:
        raise LibraryError(f"{where}: format_version {int(version)}, this build reads {NPZ_FORMAT}")
    feature_names = tuple(str(s) for s in data["feature_names"].tolist())
    if not feature_names or len(set(feature_names)) != len(feature_names):
        raise LibraryError(f"{where}: feature_names must be unique names of at least one feature, got "
                           f"{len(feature_names)} names ({len(set(feature_names))} distinct)")
    names = [str(s) for s in data["class_names"].tolist()]
    if data["features"].dtype.kind not in "fiu":  # complex parts were dropped with a warning, strings parsed
        raise LibraryError(f"{where}: features must hold numbers, got {data['features'].dtype}")
    feats = np.asarray(data["features"], dtype=np.float64)
    # int64: a uint64 demo_length turned the offsets into floats ("slice indices must be integers")
    labels, indices, lengths = (data[k].astype(np.int64) for k in ("demo_label", "demo_index", "demo_length"))
    sources = [str(s) for s in data["demo_source"].tolist()]
    n = len(labels)
    if feats.ndim != 2 or feats.shape[1] != len(feature_names):
        raise LibraryError(f"{where}: features has shape {feats.shape}, expected (N, {len(feature_names)}) for its "
                           f"{len(feature_names)} feature_names")
    if not (len(indices) == len(lengths) == len(sources) == n):
        raise LibraryError(f"{where}: demo_label/demo_index/demo_length/demo_source lengths differ")
    if not names or len(set(names)) != len(names):  # a class is named by its name everywhere (posteriors, goals)
        raise LibraryError(f"{where}: class_names must be unique names of at least one class, got {names[:10]}")
    if len({(int(a), int(b)) for a, b in zip(labels, indices, strict=True)}) != n:  # held-out splits key on it
        raise LibraryError(f"{where}: two demonstrations have the same class and index")
    if not (len(data["issue_class"]) == len(data["issue_block"]) == len(data["issue_reason"])):
        raise LibraryError(f"{where}: issue_class/issue_block/issue_reason lengths differ")
    if (n and lengths.min() < 1) or int(lengths.sum()) != feats.shape[0]:
        raise LibraryError(f"{where}: demo_length does not add up to the {feats.shape[0]} feature rows")
    if n and (labels.min() < 0 or labels.max() >= len(names)):
        raise LibraryError(f"{where}: demo_label outside 0..{len(names) - 1}")
    issues = [LibraryIssue(str(c), int(b), str(r)) for c, b, r in
              zip(data["issue_class"].tolist(), data["issue_block"].tolist(), data["issue_reason"].tolist(),
                  strict=False)]
    demos: list[Demonstration] = []
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    seen: dict[int, int] = {}  # demonstrations of each class so far: a block's number within its class
    for k in range(n):
        f = feats[offsets[k]:offsets[k + 1]].copy()
        reasons = validate_block(f, feature_names)
        label = int(labels[k])
        block = seen[label] = seen.get(label, -1) + 1
        if reasons:  # a hand-edited npz gets the same scrutiny as a CSV
            issues.append(LibraryIssue(names[label], block, f"{path.name}: npz demonstration {block} of "
                                       f"{names[label]}: " + "; ".join(reasons)))
            continue
        f.setflags(write=False)
        demos.append(Demonstration(label, names[label], int(indices[k]), f, sources[k]))
    demos.sort(key=lambda d: (d.label, d.index))
    # the file read is the source (what every message names); what it was converted from is its origin
    origin = str(data["source"]) if data["source"].ndim == 0 else ""
    return MotionLibrary(names, demos, issues, str(path), feature_names, origin=origin)
