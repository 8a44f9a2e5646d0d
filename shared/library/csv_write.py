"""Writing a library in the paper's CSV format: ``compound_<m>.csv`` per class, the set replaced whole.

Every file is written into a temporary directory beside the output first and only then renamed into
it: an interrupted write (Ctrl-C, a full disk) leaves the earlier library as it was, never some of
its class files beside some of the new one's, which would load as one valid library.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from shared.atomic_file import make_parent

from .motions import MotionLibrary

__all__ = ["write_csv_dir"]


def write_csv_dir(lib: MotionLibrary, directory: str | Path) -> list[Path]:
    """Write ``lib`` in the paper's format: ``compound_<m>.csv`` per class (index + its F features).

    Args:
        lib: The library.
        directory: Output directory (created).

    Returns:
        The files written. Any other ``compound_*.csv`` in ``directory`` (an earlier, larger library's) is
        removed: the reader takes every ``compound_<m>.csv``, and would mix the two libraries.
    """
    out = Path(directory)
    make_parent(out / "compound_0.csv")
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out))  # same file system
    try:
        for m in range(lib.n_classes):
            rows = [np.column_stack([np.arange(d.n_samples), d.features]) for d in lib.by_class(m)]
            np.savetxt(staging / f"compound_{m}.csv",
                       np.concatenate(rows) if rows else np.zeros((0, 1 + lib.n_features)), delimiter=",",
                       fmt=["%d"] + ["%.17g"] * lib.n_features)  # every float64 back as written (%.9g: 5e-9 off)
        files = [out / f"compound_{m}.csv" for m in range(lib.n_classes)]
        for path in files:  # renames only, once every file is complete
            os.replace(staging / path.name, path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    for stale in set(out.glob("compound_*.csv")) - set(files):
        stale.unlink()
    return files
