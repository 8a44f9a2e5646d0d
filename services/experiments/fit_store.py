"""A training fit cache that the report's worker processes share on disk.

``train_model``'s ``fit_cache`` holds fitted class mixtures, demonstration sweeps and class volumes, keyed by a
digest of their data and options (:mod:`services.predictor.train`). A dict shares them within one process; the
report's parts run in several worker processes (:func:`services.experiments.report.report_workers`) and each
refitted the same classes and swept the same demonstrations for its first model of a library. :class:`FitStore`
keeps every entry in memory *and* as one ``.npz`` in a directory beside the models, and :meth:`FitStore.compute`
holds an exclusive lock on the entry while it is made, so the first process computes it and the others wait and
read it.

Entries are stored as plain arrays (``np.load`` with ``allow_pickle=False``): a fitted ``GaussianMixture`` as its
constructor parameters and its learned attributes, a :class:`~services.predictor.volumes.Sweep` as its two
arrays, a volume as itself. Read back, each is the same to the bit, so a model trained from the store is the one
trained without it (tested).

The keys name the data and options of a fit, not the code that made it, so the entries live in a subdirectory
named for what else decides them (:func:`store_tag`: the model version, bumped when training changes, and the
scikit-learn and numpy versions): entries of other code are never read, and a directory of an old tag can be
deleted. An entry that cannot be read (cut short by a crash, damaged, foreign) is made again.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import zipfile
from collections.abc import Callable, Iterator, MutableMapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import sklearn
from sklearn.mixture import GaussianMixture

from services.predictor.model import MODEL_VERSION
from services.predictor.volumes import Sweep
from shared.atomic_file import atomic_write
from shared.npz_reading import NPZ_LOCK

__all__ = ["FitStore", "fit_store", "store_tag"]

_STORES: dict[str, FitStore] = {}
_FORMAT = 1  # how entries are written (:func:`_encode`)
_UNREADABLE = (OSError, EOFError, ValueError, KeyError, TypeError, zipfile.BadZipFile)


def store_tag() -> str:
    """The subdirectory of a store whose entries this code may read: store format, model, sklearn, numpy versions."""
    return f"f{_FORMAT}-model{MODEL_VERSION}-sklearn{sklearn.__version__}-numpy{np.__version__}"


def fit_store(directory: Path) -> FitStore:
    """The process's :class:`FitStore` of ``directory`` (one per directory, shared by every caller)."""
    path = Path(directory).resolve()
    if str(path) not in _STORES:
        _STORES[str(path)] = FitStore(path)
    return _STORES[str(path)]


def _encode(value: Any) -> dict[str, np.ndarray]:
    """The arrays that store ``value`` (a fitted mixture, a sweep or an array)."""
    if isinstance(value, GaussianMixture):
        learned = {k: v for k, v in vars(value).items() if k.endswith("_") and not k.startswith("_")}
        out = {f"attr_{k}": np.asarray(v) for k, v in learned.items()}
        out["params"] = np.array(json.dumps(value.get_params()))
        out["kind"] = np.array("gmm")
        return out
    if isinstance(value, Sweep):
        return {"kind": np.array("sweep"), "indices": value.indices, "last": value.last}
    if isinstance(value, np.ndarray):
        return {"kind": np.array("array"), "array": value}
    raise TypeError(f"fit store: cannot store a {type(value).__name__}")


def _decode(arrays: Any) -> Any:
    kind = str(arrays["kind"])
    if kind == "gmm":
        gmm = GaussianMixture(**json.loads(str(arrays["params"])))
        for name in arrays.files:
            if name.startswith("attr_"):
                v = arrays[name]
                setattr(gmm, name[5:], v.item() if v.ndim == 0 else v)
        return gmm
    if kind == "sweep":
        return Sweep(arrays["indices"], arrays["last"])
    if kind == "array":
        return arrays["array"]
    raise ValueError(f"fit store: unknown entry kind {kind!r}")


class FitStore(MutableMapping[str, Any]):
    """Fit cache entries in memory and in ``directory`` (one ``.npz`` per key), shared between processes.

    Args:
        directory: The store; its entries live in ``directory / store_tag()`` (created when the first is written).
    """

    def __init__(self, directory: Path) -> None:
        self.root = Path(directory)
        self.directory = self.root / store_tag()
        self._memory: dict[str, Any] = {}

    def _path(self, key: str) -> Path:
        return self.directory / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.npz"

    def _load(self, key: str) -> bool:
        """Read ``key``'s file into memory if there is one; whether it is now in memory."""
        if key in self._memory:
            return True
        path = self._path(key)
        if not path.is_file():
            return False
        try:
            with NPZ_LOCK, np.load(path, allow_pickle=False) as arrays:
                self._memory[key] = _decode(arrays)
        except _UNREADABLE:  # cut short, damaged or foreign (np.load raises each of these): computed again
            return False
        return True

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and self._load(key)

    def __getitem__(self, key: str) -> Any:
        if not self._load(key):
            raise KeyError(key)
        return self._memory[key]

    def __setitem__(self, key: str, value: Any) -> None:
        arrays = _encode(value)  # refuses what it cannot store before anything changes
        self._memory[key] = value
        with atomic_write(self._path(key), fsync=True) as handle:  # a reader (or a crash) sees the whole entry or none
            np.savez(handle, **arrays)

    def __delitem__(self, key: str) -> None:
        self._memory.pop(key, None)
        self._path(key).unlink(missing_ok=True)

    def __iter__(self) -> Iterator[str]:
        return iter(self._memory)  # the keys this process has seen (file names are digests of the keys)

    def __len__(self) -> int:
        return len(self._memory)

    @contextmanager
    def _locked(self, key: str) -> Iterator[None]:
        locks = self.directory / "locks"  # one empty file per entry, never removed (removing one races its waiters)
        locks.mkdir(parents=True, exist_ok=True)
        with open(locks / f"{self._path(key).stem}.lock", "a") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX)  # released when the file closes
            yield

    def compute(self, key: str, make: Callable[[], Any]) -> Any:
        """``key``'s entry, made with ``make()`` by the first process that asks and read by the others."""
        if self._load(key):
            return self._memory[key]
        with self._locked(key):
            if not self._load(key):  # another process may have made it while this one waited
                self[key] = make()
        return self._memory[key]
