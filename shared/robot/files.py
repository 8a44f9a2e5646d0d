"""The PR2's data files: the URDF text and the collision-sphere file (``shared/data/robot/``).

Errors in either (a missing file, bad TOML, a malformed entry), like bad configurations and IK targets
elsewhere in :mod:`shared.robot`, raise :class:`RobotModelError` with a message naming what was wrong.
"""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from shared.data_files import relative_to_cwd

__all__ = ["RobotModelError", "read_robot_file", "load_spheres"]


class RobotModelError(ValueError):
    """Bad robot model file, bad configuration (shape, NaN, outside limits) or bad IK target."""


def read_robot_file(path: str | Path | None, default: str) -> tuple[str, str]:
    """Text of a robot file and a name for messages.

    Args:
        path: A file to read; None: the embedded ``shared/data/robot/<default>``.
        default: File name of the embedded default (``"pr2.urdf"``, ``"pr2_spheres.toml"``).

    Returns:
        ``(text, source)``.

    Raises:
        RobotModelError: The file does not exist.
    """
    if path is None:
        res = resources.files("shared") / "data" / "robot" / default
        if not res.is_file():
            raise RobotModelError(f"robot data file {default!r} missing from the package")
        return res.read_text(), f"shared/data/robot/{default}"
    p = Path(path)
    if not p.is_file():
        raise RobotModelError(f"robot file {str(p)!r} not found{relative_to_cwd(p)}")
    return p.read_text(), str(p)


def load_spheres(path: str | Path | None = None) -> dict[str, Any]:
    """Read and validate the sphere file.

    Returns:
        ``{"posture": {joint: value}, "spheres": {link: (n, 4) array}, "groups": {name: [links]}, "source": str}``.

    Raises:
        RobotModelError: Missing file, bad TOML or a malformed entry (named in the message).
    """
    text, source = read_robot_file(path, "pr2_spheres.toml")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RobotModelError(f"sphere file {source}: {exc}") from None
    posture = {}
    for k, v in data.get("posture", {}).items():
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise RobotModelError(f"sphere file {source}: posture.{k} must be a finite number, got {v!r}")
        posture[k] = float(v)
    spheres = {}
    for link, rows in data.get("spheres", {}).items():
        arr = np.asarray(rows, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 4 or not np.all(np.isfinite(arr)) or np.any(arr[:, 3] <= 0):
            raise RobotModelError(f"sphere file {source}: spheres.{link} must be a list of [x, y, z, r>0]")
        spheres[link] = arr
    if not spheres:
        raise RobotModelError(f"sphere file {source}: no [spheres]")
    groups = {k: list(v) for k, v in data.get("groups", {}).items()}
    for g, links in groups.items():
        for ln in links:
            if ln not in spheres:
                raise RobotModelError(f"sphere file {source}: groups.{g} names {ln!r}, which has no spheres")
    return {"posture": posture, "spheres": spheres, "groups": groups, "source": source}
