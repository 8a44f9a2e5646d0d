"""The 3D scene of a run: the project's messages as Foxglove's well-known messages, built with ``foxglove-sdk``.

:class:`SceneBuilder` turns messages into ``foxglove.messages`` objects (``SceneUpdate``,
``FrameTransforms``, ``PointCloud``), which the SDK encodes as protobuf with the schemas it carries: the
table and cups (static), the robot's collision spheres, the predicted occupancy as a point cloud of voxel
centres with their probability and colour, the K candidate end-effector paths (the chosen one thick and
green) and the human's body as line segments. The robot and human models are optional (``None`` skips
what needs them); what the builder needs of them is written down as :class:`ArmModel`, :class:`BodyModel`
and :class:`PlaceInScene`.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Protocol

import numpy as np
from foxglove.messages import (
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    PackedElementField,
    PackedElementFieldNumericType,
    PointCloud,
    Quaternion,
    SceneEntity,
    SceneUpdate,
)
from scipy.spatial.transform import Rotation

from shared.protocol import DemoMarker, HumanPose, OccupancyGrid, Plan, RobotState
from shared.scene import Scene

from .primitives import color, point3, pose_at, spheres, timestamp, vector3

if TYPE_CHECKING:
    import torch

__all__ = ["WORLD_FRAME", "ArmModel", "BodyModel", "PlaceInScene", "SceneBuilder", "timestamp", "probability_color",
           "goal_rgb", "CLOUD_FIELDS", "CHOSEN_RGBA", "default_builder"]

log = logging.getLogger(__name__)

WORLD_FRAME = "world"

_F32, _U8 = PackedElementFieldNumericType.Float32, PackedElementFieldNumericType.Uint8
CLOUD_FIELDS: tuple[tuple[str, int, PackedElementFieldNumericType], ...] = (
    ("x", 0, _F32), ("y", 4, _F32), ("z", 8, _F32), ("probability", 12, _F32),
    ("red", 16, _U8), ("green", 17, _U8), ("blue", 18, _U8), ("alpha", 19, _U8))
"""The occupancy cloud's point layout ``(name, byte offset, type)``: the voxel centre (m, world frame), its
probability p(x|xi) in [0, 1], and its colour (:func:`probability_color`, Foxglove's ``rgba-fields`` mode)."""
_CLOUD_DTYPE = np.dtype([("xyz", "<f4", (3,)), ("p", "<f4"), ("rgba", "u1", (4,))])


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


_KEEP_FIRST_POSES = 4
"""Demonstrations whose first pose the scene builder keeps (the current one, and a few late poses of the last)."""


def _quat_from_matrix(r: np.ndarray) -> Quaternion:
    """Unit quaternion of a ``(3, 3)`` rotation matrix.

    scipy's conversion: right at half turns too, where signs taken from the off-diagonal differences (all zero
    there) are not.
    """
    x, y, z, w = Rotation.from_matrix(np.asarray(r, dtype=np.float64)[:3, :3]).as_quat()
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def probability_color(p: np.ndarray) -> np.ndarray:
    """``(N,)`` probabilities in [0, 1] -> ``(N, 4)`` RGBA: yellow (low) to red (high), more opaque when likely."""
    p = np.clip(np.asarray(p, dtype=np.float64), 0.0, 1.0)
    return np.stack([np.ones_like(p), 0.9 * (1.0 - p), np.zeros_like(p), 0.15 + 0.6 * p], axis=-1)


def _entity(entity_id: str, stamp: float, **primitives: list) -> SceneEntity:
    return SceneEntity(timestamp=timestamp(stamp), frame_id=WORLD_FRAME, id=entity_id, **primitives)


def _line(points: np.ndarray, rgba: tuple[float, float, float, float], thickness: float) -> LinePrimitive:
    return LinePrimitive(pose=pose_at([0, 0, 0]), thickness=float(thickness), scale_invariant=False,
                         points=[point3(p) for p in points], color=color(rgba))


# goal colours: a goal named after a colour is drawn in it
_NAMED = {"blue": (0.15, 0.35, 0.95), "red": (0.9, 0.15, 0.15), "green": (0.1, 0.7, 0.2),
          "yellow": (0.9, 0.8, 0.1)}
CHOSEN_RGBA = (0.1, 0.85, 0.2, 1.0)
HUMAN_RGBA = (0.25, 0.5, 0.95, 0.6)
"""The human's body while its demonstration (a reach) goes on."""
ENDED_HUMAN_RGBA = (0.1, 0.2, 0.45, 0.7)
"""The body of a demonstration that has ended: its last pose, no longer updated. A dark navy: the light grey it was
(0.55, alpha 0.35) and then a slate grey (0.35, 0.4, 0.55, alpha 0.45) both read as part of the robot's grey spheres
in `foresight log snapshot` (two reviews)."""


def goal_rgb(name: str, k: int) -> tuple[float, float, float]:
    """Colour of goal ``k`` called ``name`` (its colour word if it has one, else a tab10 colour).

    tab10 less its green (the chosen path's) and red (the red cup's) and grey (the robot's): seven, so that the
    synthetic library's eight classes (two named after cups) plot in eight colours; five gave two pairs alike.
    """
    for word, rgb in _NAMED.items():
        if word in name.lower():
            return rgb
    tab = [(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.58, 0.4, 0.74), (0.55, 0.34, 0.29), (0.89, 0.47, 0.76),
           (0.74, 0.74, 0.13), (0.09, 0.75, 0.81)]
    return tab[k % len(tab)]


class SceneBuilder:
    """Builds Foxglove scene messages from the project's messages.

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
        self._first_pose: dict[int, np.ndarray] = {}  # the placement reference of the last few demonstrations
        self._unmatched_names: set[tuple[str, ...]] = set()  # joint name lists already warned about
        self._body: tuple[int, np.ndarray, np.ndarray] | None = None  # the last body drawn: demo, segments, radii

    def note_pose(self, pose: HumanPose) -> None:
        """Every pose, drawn or not: a demonstration's first (index 0) is where the human is placed from.

        The view draws the human at most every ``viz_period_s``, so the first pose is often not drawn; the
        predictor places the human from it, and so must the picture.
        """
        if pose.index == 0:
            self._remember_first(pose)

    def placement_reference(self) -> np.ndarray | None:
        """The newest demonstration's first pose ``(12,)``, from which the human is placed (None before any)."""
        return next(reversed(self._first_pose.values()), None)

    def _remember_first(self, pose: HumanPose) -> np.ndarray:
        self._first_pose.pop(pose.demo_id, None)  # the newest last: ids restart with each replayer or tracker run
        self._first_pose[pose.demo_id] = first = pose.features.copy()
        while len(self._first_pose) > _KEEP_FIRST_POSES:  # a long session: keep the last few
            del self._first_pose[next(iter(self._first_pose))]
        return first

    # -- static scene ----------------------------------------------------------------------------

    def static_scene(self, stamp: float) -> SceneUpdate:
        """Table boxes and cups."""
        cubes = [CubePrimitive(pose=pose_at(b.center), size=vector3(b.size), color=color((0.55, 0.4, 0.25, 0.9)))
                 for b in self.scene.boxes]
        ents = [_entity("obstacles", stamp, cubes=cubes)]
        for k, cup in enumerate(self.scene.cups):
            size = vector3([2 * cup.radius, 2 * cup.radius, cup.height])
            cyl = CylinderPrimitive(pose=pose_at(cup.center), size=size, bottom_scale=1.0, top_scale=1.0,
                                    color=color((*goal_rgb(cup.name, k), 1.0)))
            ents.append(_entity(f"cup/{cup.name}", stamp, cylinders=[cyl]))
        return SceneUpdate(entities=ents)

    def base_transform(self, stamp: float) -> FrameTransforms:
        """The transform world -> robot_base (from the scene)."""
        return FrameTransforms(transforms=[self._tf(stamp, "robot_base", self.scene.robot.base_transform())])

    @staticmethod
    def _tf(stamp: float, child: str, t: np.ndarray) -> FrameTransform:
        return FrameTransform(timestamp=timestamp(stamp), parent_frame_id=WORLD_FRAME, child_frame_id=child,
                              translation=vector3(t[:3, 3]), rotation=_quat_from_matrix(t[:3, :3]))

    # -- robot -----------------------------------------------------------------------------------

    def _to_robot_order(self, q: np.ndarray, names: list[str]) -> np.ndarray | None:
        """``(..., D)`` in the message's joint order -> the robot model's order (None if they differ)."""
        model = list(self.robot.joint_names)  # type: ignore[union-attr] - called only with a robot
        if list(names) == model:
            return q
        if sorted(names) != sorted(model):
            if tuple(names) not in self._unmatched_names:  # once per list: every robot state would say it again
                self._unmatched_names.add(tuple(names))
                log.warning("viz: joint names %s do not match the robot model's %s; such states are not drawn",
                            names, model)
            return None
        idx = [list(names).index(n) for n in model]
        return q[..., idx]

    def _torch(self, q: np.ndarray) -> torch.Tensor:
        import torch

        lower = self.robot.lower  # type: ignore[union-attr] - called only with a robot
        return torch.as_tensor(q, dtype=lower.dtype, device=lower.device)

    def robot_spheres(self, state: RobotState, stamp: float | None = None) -> SceneUpdate | None:
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
        return SceneUpdate(entities=[_entity("robot/spheres", state.stamp if stamp is None else stamp,
                                             spheres=spheres(centers, radii, rgba))])

    def end_effector_transform(self, state: RobotState, stamp: float | None = None) -> FrameTransforms | None:
        """The transform world -> end_effector at ``state.q``, stamped ``stamp`` (default: ``state.stamp``)."""
        if self.robot is None:
            return None
        q = self._to_robot_order(state.q, state.joint_names)
        if q is None:
            return None
        t = self.robot.end_effector(self._torch(q)).detach().cpu().numpy().astype(np.float64)
        return FrameTransforms(transforms=[self._tf(state.stamp if stamp is None else stamp, "end_effector", t)])

    def plan_paths(self, plan: Plan, stamp: float | None = None) -> SceneUpdate | None:
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
        return SceneUpdate(entities=[_entity("plan/paths", plan.stamp if stamp is None else stamp, lines=lines)])

    # -- occupancy -------------------------------------------------------------------------------

    def occupancy_voxels(self, occ: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
        """``(centres (N, 3), probabilities (N,))`` of the voxels drawn: p >= min_probability, at most max_voxels."""
        p = occ.values.astype(np.float64) / 255.0
        keep = np.flatnonzero(p >= self.min_probability)
        if keep.size > self.max_voxels:
            keep = keep[np.argsort(-p[keep], kind="stable")[: self.max_voxels]]
        ijk = np.stack(np.unravel_index(occ.indices[keep].astype(np.int64), tuple(int(d) for d in occ.dims)), axis=-1)
        return occ.origin + occ.resolution * (ijk + 0.5), p[keep]

    def occupancy_cloud(self, occ: OccupancyGrid, stamp: float | None = None) -> PointCloud:
        """The drawn voxels (:meth:`occupancy_voxels`) as a point cloud, points laid out as :data:`CLOUD_FIELDS`.

        Stamped ``stamp`` (default: ``occ.stamp``); Foxglove draws each point as a cube of the voxel's size when
        the layout says so (docs/foresight.foxglove.json).
        """
        centers, p = self.occupancy_voxels(occ)
        points = np.empty(len(p), dtype=_CLOUD_DTYPE)
        points["xyz"] = centers
        points["p"] = p
        points["rgba"] = np.round(probability_color(p) * 255.0)
        fields = [PackedElementField(name=name, offset=offset, type=kind) for name, offset, kind in CLOUD_FIELDS]
        return PointCloud(timestamp=timestamp(occ.stamp if stamp is None else stamp), frame_id=WORLD_FRAME,
                          pose=pose_at([0, 0, 0]), point_stride=_CLOUD_DTYPE.itemsize, fields=fields,
                          data=points.tobytes())

    # -- human -----------------------------------------------------------------------------------

    def human_body(self, pose: HumanPose, stamp: float | None = None) -> SceneUpdate | None:
        """The human's body capsules' axes as line segments as thick as the limbs, in the scene frame.

        Stamped ``stamp`` (default: ``pose.stamp``).
        """
        if self.human is None or self.place is None:
            return None
        self.note_pose(pose)
        first = self._first_pose.get(pose.demo_id)
        if first is None:  # joined after the demonstration's first pose: placed from the first one seen
            first = self._remember_first(pose)
        feats = self.place(pose.features, first, self.scene)
        ends, radii = self.human.capsules(feats)  # (S, 2, 3), (S,)
        ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2, 3)
        radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        self._body = (pose.demo_id, ends, radii)
        return self._body_update(ends, radii, HUMAN_RGBA, pose.stamp if stamp is None else stamp)

    def human_ended(self, marker: DemoMarker, stamp: float | None = None) -> SceneUpdate | None:
        """At a demonstration's end (or loss) marker, its last drawn body again in grey: no pose updates it any more.

        A live tracker publishes poses during reaches (and briefly the person at rest), so its last reach's body
        stayed on show, as if live, while the person moved on or left. None for a start marker, or when no body of
        that demonstration is drawn.
        """
        if marker.event not in ("end", "lost") or self._body is None or self._body[0] != marker.demo_id:
            return None
        _, ends, radii = self._body
        return self._body_update(ends, radii, ENDED_HUMAN_RGBA, marker.stamp if stamp is None else stamp)

    def _body_update(self, ends: np.ndarray, radii: np.ndarray, rgba: tuple[float, float, float, float],
                     stamp: float) -> SceneUpdate:
        lines = [_line(seg, rgba, 2.0 * r) for seg, r in zip(ends, radii, strict=True)]
        return SceneUpdate(entities=[_entity("human/body", stamp, lines=lines)])


def default_builder(scene: Scene, device: str = "cpu") -> SceneBuilder:
    """The builder of a run's scene: the PR2 placed in ``scene`` and the human model (``shared.human``)."""
    import torch

    from shared.human import HumanModel, place_in_scene
    from shared.robot import PR2

    return SceneBuilder(scene, PR2.from_scene(scene, device=device, dtype=torch.float32), HumanModel(),
                        place_in_scene)
