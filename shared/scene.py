"""Scene file: where the human, the robot, the table, the cups and the voxel grid are.

Every service loads the same scene file (TOML; default: the embedded ``pr2_two_cups.toml``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shared.data_files import finite_vector, read_toml
from shared.protocol.limits import MAX_GOALS, MAX_STRING_CHARS

__all__ = ["SceneError", "Box", "Cup", "Grid", "HumanPlacement", "RobotPlacement", "Scene", "load_scene",
           "DEFAULT_SCENE", "PAPER_SCENES", "embedded_scenes", "SCENE_HELP"]

DEFAULT_SCENE = "pr2_two_cups"

PAPER_SCENES = {"PR2TwoCups": "pr2_two_cups", "PR2TwoCupsFacing": "pr2_two_cups_facing",
                "PR2TwoCupsSide": "pr2_two_cups_side", "PR2TwoCupsSideParallel": "pr2_two_cups_side_parallel"}
"""The paper's Move3D scene names and the embedded scene files written from them (docs/scenes.md)."""

SCENE_HELP = ("scene: an embedded name (pr2_two_cups, pr2_two_cups_facing, pr2_two_cups_side, "
              "pr2_two_cups_side_parallel, or the paper's PR2TwoCups, PR2TwoCupsFacing, PR2TwoCupsSide, "
              "PR2TwoCupsSideParallel) or a scene TOML file")
"""``--help`` text of every ``--scene`` option."""


class SceneError(ValueError):
    """The scene file is missing or malformed; the message names the entry."""


@dataclass(frozen=True)
class Box:
    """Axis-aligned box obstacle: ``center`` and full ``size`` (m), both ``(3,)``."""

    name: str
    center: np.ndarray
    size: np.ndarray

    @property
    def lower(self) -> np.ndarray:
        """``(3,)`` lower corner."""
        return self.center - self.size / 2

    @property
    def upper(self) -> np.ndarray:
        """``(3,)`` upper corner."""
        return self.center + self.size / 2


@dataclass(frozen=True)
class Cup:
    """Upright cylinder: ``position`` is the centre of its base disc (m).

    ``goal_arm``, when the scene gives it, is the robot's goal configuration for reaching this cup (the
    paper's scenes record one per task); the planner then uses it instead of a pre-grasp found by IK.
    """

    name: str
    position: np.ndarray
    radius: float
    height: float
    goal_arm: np.ndarray | None = None  # (7,) the robot's right-arm goal configuration for this cup (rad), optional

    @property
    def center(self) -> np.ndarray:
        """``(3,)`` centre of the cylinder."""
        return self.position + np.array([0.0, 0.0, self.height / 2])


@dataclass(frozen=True)
class Grid:
    """Regular voxel grid: voxel (i, j, k) spans ``min + res * [i, i+1)`` per axis."""

    min: np.ndarray
    max: np.ndarray
    resolution: float

    @property
    def dims(self) -> tuple[int, int, int]:
        """Voxel counts ``(nx, ny, nz)``; the max bound is rounded up to whole voxels."""
        n = np.ceil((self.max - self.min) / self.resolution - 1e-9).astype(int)
        return int(n[0]), int(n[1]), int(n[2])

    @property
    def origin(self) -> np.ndarray:
        """``(3,)`` lower corner of voxel (0, 0, 0)."""
        return self.min

    def centers(self) -> np.ndarray:
        """``(nx, ny, nz, 3)`` voxel centre coordinates."""
        axes = [self.min[a] + self.resolution * (np.arange(n) + 0.5) for a, n in enumerate(self.dims)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def index(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Voxel indices of points.

        A point on a voxel face belongs to the voxel above it: ``(p - min) / res`` is floored with a 1e-9 (of a
        voxel) tolerance, as :attr:`dims` rounds, since the division's rounding put 16 of the 47 inner x faces (as
        decimals: -0.9) of a grid from -1 m at 0.05 m in the voxel below (-0.9 gave 1.9999999999999996).

        Args:
            points: ``(..., 3)`` positions (m).

        Returns:
            ``(idx, inside)``: ``(..., 3)`` int indices (clipped) and ``(...)`` bool, true where the
            point lies inside the grid.
        """
        idx = np.floor((points - self.min) / self.resolution + 1e-9).astype(np.int64)
        dims = np.asarray(self.dims)
        inside = np.all((idx >= 0) & (idx < dims), axis=-1)
        return np.clip(idx, 0, dims - 1), inside

    def with_resolution(self, resolution: float) -> Grid:
        """The same bounds at another resolution."""
        return Grid(self.min, self.max, float(resolution))


@dataclass(frozen=True)
class HumanPlacement:
    """World pose of the observed human's first pelvis pose."""

    pelvis_xyz: np.ndarray
    pelvis_yaw: float  # radians


@dataclass(frozen=True)
class RobotPlacement:
    """PR2 base pose in the world and its torso lift."""

    base_xy: np.ndarray
    base_yaw: float  # radians
    torso_lift: float
    start_arm: np.ndarray | None = None  # (7,) right-arm start configuration (rad), optional

    def base_transform(self) -> np.ndarray:
        """``(4, 4)`` world-from-base transform."""
        c, s = math.cos(self.base_yaw), math.sin(self.base_yaw)
        t = np.eye(4)
        t[:2, :2] = [[c, -s], [s, c]]
        t[:2, 3] = self.base_xy
        return t


@dataclass(frozen=True)
class Scene:
    """A loaded scene (see ``shared/data/scenes/*.toml``)."""

    name: str
    human: HumanPlacement
    robot: RobotPlacement
    boxes: tuple[Box, ...]
    cups: tuple[Cup, ...]
    grid: Grid
    workspace: Grid
    source: str = field(default="")
    paper_name: str = field(default="")

    @property
    def ref(self) -> str:
        """What :func:`load_scene` takes to load this scene again: its embedded name, else its file path."""
        return self.name if self.source == f"{self.name}.toml" else self.source

    def text(self) -> str | None:
        """The scene file's text (its file, else the embedded one of that name), or None where neither is found."""
        from importlib import resources

        path = Path(self.source)
        if path.is_file():
            return path.read_text()
        res = resources.files("shared") / "data" / "scenes" / path.name
        return res.read_text() if res.is_file() else None

    def cup(self, name: str) -> Cup:
        """The cup called ``name``."""
        for c in self.cups:
            if c.name == name:
                return c
        raise SceneError(f"scene {self.name}: no cup named {name!r} (have {[c.name for c in self.cups]})")


def _vec(where: str, raw: Any, n: int) -> np.ndarray:
    return finite_vector(where, raw, n, SceneError)


def _num(where: str, raw: Any, positive: bool = False) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        raise SceneError(f"{where}: expected a finite number, got {raw!r}")
    if positive and raw <= 0:
        raise SceneError(f"{where}: must be > 0, got {raw!r}")
    return float(raw)


def _table(where: str, data: dict[str, Any], key: str) -> Any:
    if key not in data:
        raise SceneError(f"{where}: missing [{key}]")
    return data[key]


def _grid(where: str, raw: dict[str, Any], default_res: float | None = None) -> Grid:
    lo, hi = _vec(f"{where}.min", raw.get("min"), 3), _vec(f"{where}.max", raw.get("max"), 3)
    if np.any(hi <= lo):
        raise SceneError(f"{where}: max {hi.tolist()} must exceed min {lo.tolist()} on every axis")
    res = raw.get("resolution", default_res)
    return Grid(lo, hi, _num(f"{where}.resolution", res, positive=True))


def parse_scene(data: dict[str, Any], source: str = "<scene>") -> Scene:
    """Build a :class:`Scene` from parsed TOML, validating every entry."""
    h = _table(source, data, "human")
    r = _table(source, data, "robot")
    human = HumanPlacement(_vec(f"{source}: human.pelvis_xyz", h.get("pelvis_xyz"), 3),
                           math.radians(_num(f"{source}: human.pelvis_yaw_deg", h.get("pelvis_yaw_deg"))))
    robot = RobotPlacement(_vec(f"{source}: robot.base_xy", r.get("base_xy"), 2),
                           math.radians(_num(f"{source}: robot.base_yaw_deg", r.get("base_yaw_deg"))),
                           _num(f"{source}: robot.torso_lift", r.get("torso_lift")),
                           _vec(f"{source}: robot.start_arm", r["start_arm"], 7) if "start_arm" in r else None)
    boxes = []
    for i, b in enumerate(data.get("boxes", [])):
        where = f"{source}: boxes[{i}]"
        size = _vec(f"{where}.size", b.get("size"), 3)
        if np.any(size <= 0):
            raise SceneError(f"{where}.size: must be positive, got {size.tolist()}")
        boxes.append(Box(str(b.get("name", f"box{i}")), _vec(f"{where}.center", b.get("center"), 3), size))
    cups = []
    for i, c in enumerate(data.get("cups", [])):
        where = f"{source}: cups[{i}]"
        if "name" not in c:
            raise SceneError(f"{where}: missing name")
        cups.append(Cup(str(c["name"]), _vec(f"{where}.position", c.get("position"), 3),
                        _num(f"{where}.radius", c.get("radius", 0.04), positive=True),
                        _num(f"{where}.height", c.get("height", 0.10), positive=True),
                        _vec(f"{where}.goal_arm", c["goal_arm"], 7) if "goal_arm" in c else None))
    if len({c.name for c in cups}) != len(cups):
        raise SceneError(f"{source}: cup names must be unique")
    _check_goals(source, cups)
    grid = _grid(f"{source}: grid", _table(source, data, "grid"))
    workspace = _grid(f"{source}: workspace", data.get("workspace", {"min": grid.min, "max": grid.max}),
                      grid.resolution)
    return Scene(str(data.get("name", Path(source).stem)), human, robot, tuple(boxes), tuple(cups), grid,
                 workspace, source, str(data.get("paper_name", "")))


def _check_goals(source: str, cups: list[Cup]) -> None:
    """Refuse cups a plan could not carry: every cup is a goal, its name sent with every plan (docs/protocol.md)."""
    if len(cups) > MAX_GOALS:
        raise SceneError(f"{source}: {len(cups)} cups, over the wire's limit of {MAX_GOALS} goals per plan")
    for i, c in enumerate(cups):
        if not c.name or len(c.name) > MAX_STRING_CHARS:
            raise SceneError(f"{source}: cups[{i}].name has {len(c.name)} characters; goal names are sent with every "
                             f"plan and must have 1 to {MAX_STRING_CHARS}")


def load_scene(path: str | Path | None = None) -> Scene:
    """Load a scene file; ``None`` or a bare name loads an embedded scene.

    A bare name is an embedded scene's file name (``pr2_two_cups_facing``) or the paper's scene name
    (``PR2TwoCupsFacing``, :data:`PAPER_SCENES`, any letter case).

    Raises:
        SceneError: If the file is missing, not TOML, or has a bad entry.
    """
    if isinstance(path, str) and "/" not in path and not path.endswith(".toml"):
        by_paper = {k.lower(): v for k, v in PAPER_SCENES.items()}
        path = by_paper.get(path.lower(), path)
        if path not in embedded_scenes():
            raise SceneError(f"no embedded scene named {path!r} (have {', '.join(embedded_scenes())}, or the paper's "
                             f"{', '.join(PAPER_SCENES)}; or give a scene file path)")
    data, source = read_toml(path, "scenes", DEFAULT_SCENE, "scene file", SceneError)
    return parse_scene(data, source)


def embedded_scenes() -> list[str]:
    """Names of the scene files that ship with Foresight (``shared/data/scenes/*.toml``), sorted."""
    from importlib import resources

    folder = resources.files("shared") / "data" / "scenes"
    return sorted(p.name[: -len(".toml")] for p in folder.iterdir() if p.name.endswith(".toml"))
