"""The Foxglove conversion: the project's messages as scene entities for Foxglove's 3D panel.

:class:`SceneBuilder` turns messages into ``foxglove.SceneUpdate`` / ``foxglove.FrameTransforms``
objects (JSON-ready dicts; their schemas are in :mod:`shared.recording.schemas`): the table and cups
(static), the robot's collision spheres, occupied voxels as cubes coloured by probability, the K
candidate end-effector paths (the chosen one thick and green) and the human's body as line segments.
The robot and human models are optional (``None`` skips what needs them); what the builder needs of
them is written down as :class:`ArmModel`, :class:`BodyModel` and :class:`PlaceInScene`.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from shared.protocol import HumanPose, OccupancyGrid, Plan, RobotState
from shared.scene import Scene

if TYPE_CHECKING:
    import torch

__all__ = [
    "WORLD_FRAME",
    "ArmModel",
    "BodyModel",
    "PlaceInScene",
    "SceneBuilder",
    "time_of",
    "probability_color",
    "goal_rgb",
]

log = logging.getLogger(__name__)

WORLD_FRAME = "world"


class ArmModel(Protocol):
    """What the builder needs of a robot model (``shared.robot.PR2`` is one).

    ``q`` has the model's joint order (``joint_names``), shape ``(..., D)``, and the dtype and device
    of ``lower``.
    """

    joint_names: list[str]
    lower: torch.Tensor  # (D,) joint lower limits
    sphere_radii: torch.Tensor  # (S,) collision sphere radii (m)

    def sphere_centers(self, q: torch.Tensor) -> torch.Tensor:
        """``(..., S, 3)`` collision sphere centres at ``q``."""
        ...

    def end_effector(self, q: torch.Tensor) -> torch.Tensor:
        """``(..., 4, 4)`` end-effector pose at ``q`` in the scene frame."""
        ...


class BodyModel(Protocol):
    """What the builder needs of a human model (``shared.human.HumanModel`` is one)."""

    def capsules(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(ends (S, 2, 3), radii (S,))``: the body's capsules at a scene-frame posture ``(12,)``."""
        ...


class PlaceInScene(Protocol):
    """Moves recorder-frame postures into the scene (``shared.human.place_in_scene`` is one)."""

    def __call__(self, features: np.ndarray, first_pose: np.ndarray, scene: Scene) -> np.ndarray:
        """``(..., 12)`` scene-frame postures of ``features (..., 12)``, relative to ``first_pose (12,)``."""
        ...


# ----------------------------------------------------------------------------------------------
# primitives


def time_of(seconds: float) -> dict[str, int]:
    """``{"sec", "nsec"}`` of a non-negative time in seconds."""
    ns = max(0, int(round(seconds * 1e9)))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _v(p: np.ndarray | list[float]) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def _c(rgba: tuple[float, float, float, float]) -> dict[str, float]:
    return {"r": float(rgba[0]), "g": float(rgba[1]), "b": float(rgba[2]), "a": float(rgba[3])}


_IDENTITY_Q = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def _pose_at(p: np.ndarray | list[float], q: dict[str, float] | None = None) -> dict[str, Any]:
    return {"position": _v(p), "orientation": dict(q or _IDENTITY_Q)}


def _quat_from_matrix(r: np.ndarray) -> dict[str, float]:
    """Unit quaternion of a ``(3, 3)`` rotation matrix."""
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    return {"x": x / n, "y": y / n, "z": z / n, "w": w / n}


def probability_color(p: np.ndarray) -> np.ndarray:
    """``(N,)`` probabilities in [0, 1] -> ``(N, 4)`` RGBA: yellow (low) to red (high), more opaque when likely."""
    p = np.clip(np.asarray(p, dtype=np.float64), 0.0, 1.0)
    return np.stack([np.ones_like(p), 0.9 * (1.0 - p), np.zeros_like(p), 0.15 + 0.6 * p], axis=-1)


def _entity(entity_id: str, stamp: float, **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    ent: dict[str, Any] = {"timestamp": time_of(stamp), "frame_id": WORLD_FRAME, "id": entity_id,
                           "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False, "metadata": []}
    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        ent[kind] = primitives.get(kind, [])
    return ent


def _update(*entities: dict[str, Any]) -> dict[str, Any]:
    return {"deletions": [], "entities": list(entities)}


def _line(points: np.ndarray, rgba: tuple[float, float, float, float], thickness: float,
          kind: int = 0) -> dict[str, Any]:
    return {"type": kind, "pose": _pose_at([0, 0, 0]), "thickness": float(thickness), "scale_invariant": False,
            "points": [_v(p) for p in points], "color": _c(rgba), "colors": [], "indices": []}


# goal colours: a goal named after a colour is drawn in it
_NAMED = {"blue": (0.15, 0.35, 0.95), "red": (0.9, 0.15, 0.15), "green": (0.1, 0.7, 0.2),
          "yellow": (0.9, 0.8, 0.1)}
CHOSEN_RGBA = (0.1, 0.85, 0.2, 1.0)


def goal_rgb(name: str, k: int) -> tuple[float, float, float]:
    """Colour of goal ``k`` called ``name`` (its colour word if it has one, else a tab10 colour)."""
    for word, rgb in _NAMED.items():
        if word in name.lower():
            return rgb
    tab = [(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.58, 0.4, 0.74), (0.55, 0.34, 0.29), (0.89, 0.47, 0.76)]
    return tab[k % len(tab)]


class SceneBuilder:
    """Builds Foxglove scene updates from the project's messages.

    Args:
        scene: The scene (table, cups, robot base, human placement).
        robot: Robot model (shared.robot.PR2), or None: no robot spheres, paths or end-effector frame.
        human: Human model (shared.human.HumanModel), or None: no human body.
        place: Scene placement of postures (shared.human.place_in_scene), or None: no human body.
        min_probability: Voxels below this probability are not drawn.
        max_voxels: At most this many voxels are drawn (the most probable ones).
    """

    def __init__(self, scene: Scene, robot: ArmModel | None = None, human: BodyModel | None = None,
                 place: PlaceInScene | None = None,
                 min_probability: float = 0.05, max_voxels: int = 20000) -> None:
        self.scene = scene
        self.robot = robot
        self.human = human
        self.place = place
        self.min_probability = min_probability
        self.max_voxels = max_voxels
        self._first_pose: dict[int, np.ndarray] = {}

    # -- static scene ----------------------------------------------------------------------------

    def static_scene(self, stamp: float) -> dict[str, Any]:
        """Table boxes and cups."""
        cubes = [{"pose": _pose_at(b.center), "size": _v(b.size), "color": _c((0.55, 0.4, 0.25, 0.9))}
                 for b in self.scene.boxes]
        ents = [_entity("obstacles", stamp, cubes=cubes)]
        for k, cup in enumerate(self.scene.cups):
            rgb = goal_rgb(cup.name, k)
            cyl = {"pose": _pose_at(cup.center), "size": _v([2 * cup.radius, 2 * cup.radius, cup.height]),
                   "bottom_scale": 1.0, "top_scale": 1.0, "color": _c((*rgb, 1.0))}
            ents.append(_entity(f"cup/{cup.name}", stamp, cylinders=[cyl]))
        return _update(*ents)

    def base_transform(self, stamp: float) -> dict[str, Any]:
        """FrameTransforms world -> robot_base (from the scene)."""
        t = self.scene.robot.base_transform()
        return {"transforms": [self._tf(stamp, WORLD_FRAME, "robot_base", t)]}

    @staticmethod
    def _tf(stamp: float, parent: str, child: str, t: np.ndarray) -> dict[str, Any]:
        return {"timestamp": time_of(stamp), "parent_frame_id": parent, "child_frame_id": child,
                "translation": _v(t[:3, 3]), "rotation": _quat_from_matrix(t[:3, :3])}

    # -- robot -----------------------------------------------------------------------------------

    def _to_robot_order(self, q: np.ndarray, names: list[str]) -> np.ndarray | None:
        """``(..., D)`` in the message's joint order -> the robot model's order (None if they differ)."""
        model = list(self.robot.joint_names)
        if list(names) == model:
            return q
        if sorted(names) != sorted(model):
            log.warning("viz: joint names %s do not match the robot model's %s", names, model)
            return None
        idx = [list(names).index(n) for n in model]
        return q[..., idx]

    def _torch(self, q: np.ndarray) -> torch.Tensor:
        import torch

        lower = self.robot.lower  # type: ignore[union-attr] - called only with a robot
        return torch.as_tensor(q, dtype=lower.dtype, device=lower.device)

    def robot_spheres(self, state: RobotState, stamp: float | None = None) -> dict[str, Any] | None:
        """The robot's collision spheres at ``state.q`` (grey; orange while holding).

        Stamped ``stamp`` (default: ``state.stamp``).
        """
        if self.robot is None:
            return None
        q = self._to_robot_order(state.q, state.joint_names)
        if q is None:
            return None
        centers = self.robot.sphere_centers(self._torch(q)).detach().cpu().numpy().reshape(-1, 3)
        radii = np.asarray(self.robot.sphere_radii.detach().cpu().numpy()).reshape(-1)
        rgba = (1.0, 0.6, 0.1, 0.8) if state.holding else (0.75, 0.75, 0.8, 0.8)
        spheres = [{"pose": _pose_at(c), "size": _v([2 * r] * 3), "color": _c(rgba)} for c, r in zip(centers, radii,
                                                                                                         strict=True)]
        return _update(_entity("robot/spheres", state.stamp if stamp is None else stamp, spheres=spheres))

    def end_effector_transform(self, state: RobotState, stamp: float | None = None) -> dict[str, Any] | None:
        """FrameTransforms world -> end_effector at ``state.q``, stamped ``stamp`` (default: ``state.stamp``)."""
        if self.robot is None:
            return None
        q = self._to_robot_order(state.q, state.joint_names)
        if q is None:
            return None
        t = self.robot.end_effector(self._torch(q)).detach().cpu().numpy().astype(np.float64)
        return {"transforms": [self._tf(state.stamp if stamp is None else stamp, WORLD_FRAME, "end_effector", t)]}

    def plan_paths(self, plan: Plan, stamp: float | None = None) -> dict[str, Any] | None:
        """The K candidate end-effector paths; the chosen one thick and green, invalid ones grey.

        Stamped ``stamp`` (default: ``plan.stamp``).
        """
        if self.robot is None:
            return None
        q = self._to_robot_order(plan.trajectories.astype(np.float64), plan.joint_names)
        if q is None:
            return None
        ee = self.robot.end_effector(self._torch(q)).detach().cpu().numpy()[..., :3, 3]  # (K, T, 3)
        lines = []
        for k in range(ee.shape[0]):
            if k == plan.chosen:
                rgba, width = CHOSEN_RGBA, 0.015
            elif not bool(plan.valid[k]):
                rgba, width = (0.5, 0.5, 0.5, 0.5), 0.004
            else:
                rgba, width = (*goal_rgb(plan.goal_names[k], k), 0.8), 0.006
            lines.append(_line(ee[k], rgba, width))
        return _update(_entity("plan/paths", plan.stamp if stamp is None else stamp, lines=lines))

    # -- occupancy -------------------------------------------------------------------------------

    def occupancy_cubes(self, occ: OccupancyGrid, stamp: float | None = None) -> dict[str, Any]:
        """Occupied voxels (p >= min_probability, at most max_voxels) as cubes coloured by probability.

        Stamped ``stamp`` (default: ``occ.stamp``).
        """
        p = occ.values.astype(np.float64) / 255.0
        keep = np.flatnonzero(p >= self.min_probability)
        if keep.size > self.max_voxels:
            keep = keep[np.argsort(-p[keep], kind="stable")[: self.max_voxels]]
        dims = tuple(int(d) for d in occ.dims)
        ijk = np.stack(np.unravel_index(occ.indices[keep].astype(np.int64), dims), axis=-1)
        centers = occ.origin + occ.resolution * (ijk + 0.5)
        colors = probability_color(p[keep])
        size = _v([occ.resolution] * 3)
        cubes = [{"pose": _pose_at(c), "size": size, "color": _c(tuple(col))} for c, col in zip(centers, colors,
                                                                                                 strict=True)]
        return _update(_entity("occupancy", occ.stamp if stamp is None else stamp, cubes=cubes))

    # -- human -----------------------------------------------------------------------------------

    def human_body(self, pose: HumanPose, stamp: float | None = None) -> dict[str, Any] | None:
        """The human's body capsules' axes as line segments, in the scene frame.

        Stamped ``stamp`` (default: ``pose.stamp``).
        """
        if self.human is None or self.place is None:
            return None
        first = self._first_pose.setdefault(pose.demo_id, pose.features.copy())
        if pose.index == 0:
            self._first_pose[pose.demo_id] = first = pose.features.copy()
        feats = self.place(pose.features, first, self.scene)
        ends, radii = self.human.capsules(feats)  # (S, 2, 3), (S,)
        ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2, 3)
        radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        # one line per capsule, as thick as the limb (metres, not pixels)
        lines = [_line(seg, (0.25, 0.5, 0.95, 0.6), 2.0 * r) for seg, r in zip(ends, radii, strict=True)]
        return _update(_entity("human/body", pose.stamp if stamp is None else stamp, lines=lines))
