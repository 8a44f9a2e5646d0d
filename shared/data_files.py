"""TOML data files that ship with Foresight (``shared/data/<folder>/<name>.toml``) or live elsewhere."""

from __future__ import annotations

import os
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["read_toml", "finite_vector", "relative_to_cwd"]


def read_toml(spec: str | Path | None, folder: str, default: str, what: str,
              error: type[Exception]) -> tuple[dict[str, Any], str]:
    """Read an embedded data file by bare name, or any TOML file by path.

    Args:
        spec: ``None`` (the default file), a bare name such as ``"pr2_two_cups"`` (an embedded file
            of ``shared/data/<folder>/``), or a path (anything with a ``/`` or ending in ``.toml``).
        folder: Folder of the embedded files, e.g. ``"scenes"``.
        default: Name of the default embedded file.
        what: What the file is, for error messages (e.g. ``"scene file"``).
        error: Exception type raised with a one-line message naming the file.

    Returns:
        ``(parsed TOML, source)``: ``source`` is the embedded file's name or the path.
    """
    if spec is None or (isinstance(spec, str) and "/" not in spec and not spec.endswith(".toml")):
        name = spec or default
        res = resources.files("shared") / "data" / folder / f"{name}.toml"
        if not res.is_file():
            raise error(f"no embedded {what} named {name!r}")
        text, source = res.read_text(), f"{name}.toml"
    else:
        p = Path(spec)
        if not p.is_file():
            raise error(f"{what} {str(p)!r} not found{relative_to_cwd(p)}")
        text, source = p.read_text(), str(p)
    try:
        return tomllib.loads(text), source
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{what} {source!r}: {exc}") from None


def relative_to_cwd(path: str | os.PathLike[str]) -> str:
    """`` (relative to the working directory DIR)`` for a relative path, else "": for a "not found" message.

    A relative path in a config file is read from the command's working directory, not the file's: a service
    started elsewhere (a systemd unit, another shell) said only "library 'small.npz' not found".
    """
    return "" if Path(path).is_absolute() else f" (relative to the working directory {os.getcwd()})"


def finite_vector(where: str, raw: Any, n: int, error: type[Exception]) -> np.ndarray:
    """``raw`` as ``(n,)`` finite float64 numbers, else ``error`` naming ``where``."""
    try:
        arr = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError):
        raise error(f"{where}: expected {n} numbers, got {raw!r}") from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise error(f"{where}: expected {n} finite numbers, got {raw!r}")
    return arr
