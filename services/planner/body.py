"""The person's body as last seen, as a clearance the planner keeps (real time; beyond the paper).

The human term keeps the robot out of where the person is *predicted* to be, read from 5 cm voxels at the
robot's sphere centres: a sphere pays nothing until its centre nears an occupied voxel, so a plan may pass a few
centimetres from the arm the person holds still. The executor's separation guard (``services.executor.separation``)
then holds the robot once it is within ``stop_m`` of the body and the next step would close in, and a planner that
does not know it proposed the same path again at every step and waited beside the person (docs/executor.md, "What
it does not see"). The body term is the guard's measure in the planner: the clearance between each arm-carried
sphere and the nearest capsule of the human model posed by the newest ``HumanPose`` (placed as the predictor and the
guard place it), costed with the obstacle term's smooth hinge below ``CostConfig.body_clearance`` (quadratic over its
outer half, linear within the inner half: at the default 0.10 m, within the guard's 0.05 m) and weighted like an
obstacle (``w_obstacle``). The robot keeps away from the person as they are now; the prediction keeps it away from
where they are going. The plans' ``obstacle`` cost includes it.

The newest pose alone, where the guard takes the nearest body of every pose of its last ``window_s`` (0.5 s), by
design: the window is the guard's defence against a pose's noise, which the term's 5 cm over ``stop_m`` covers, and
its older bodies are where the person has been, which the guard lets the robot into once they leave the window.
Costed against the window's bodies in closed loops of the pure cores (docs/planner.md, "The newest pose, not the
guard's window"), the robot was held less only under noise drawn afresh for every pose (which the tracker's filter
removes), as often otherwise, and reached its goal up to 0.7 s later where the person moved off its way; and 15
bodies (a 30 Hz tracker's half second) are 15 times the capsules of a kernel compiled for one body.

Real time only: a lock-step run measures the paper's planners (``PlannerServiceConfig.planner_config`` and the
experiments set ``body_clearance`` to 0), and without a pose the term is 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from shared.human import HumanModel, StreamPlacement

__all__ = ["BodyCapsules", "PersonBody", "body_clearances", "FAR_M"]

FAR_M = 1e3
"""Where the kernel's body lies while no pose has come (m from the origin): its term is then exactly 0."""


@dataclass(frozen=True)
class BodyCapsules:
    """The person's body as the costs read it.

    Attributes:
        ends: ``(C, 2, 3)`` capsule end points in the scene frame (m).
        radii: ``(C,)`` capsule radii (m).
    """

    ends: torch.Tensor
    radii: torch.Tensor

    @classmethod
    def build(cls, ends: np.ndarray, radii: np.ndarray, device: torch.device | str,
              dtype: torch.dtype) -> BodyCapsules:
        """From the human model's ``capsules``: ``ends`` ``(C, 2, 3)``, ``radii`` ``(C,)``.

        Raises:
            ValueError: Wrong shapes, or a value that is not finite.
        """
        e, r = np.asarray(ends, dtype=np.float64), np.asarray(radii, dtype=np.float64)
        if e.ndim != 3 or e.shape[1:] != (2, 3) or r.shape != (e.shape[0],):
            raise ValueError(f"body capsules must be ends (C, 2, 3) and radii (C,), got {e.shape} and {r.shape}")
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(r))):
            raise ValueError("body capsules contain NaN or inf")
        return cls(torch.as_tensor(e, device=device, dtype=dtype), torch.as_tensor(r, device=device, dtype=dtype))

    @classmethod
    def far(cls, count: int, device: torch.device | str, dtype: torch.dtype) -> BodyCapsules:
        """``count`` capsules ``FAR_M`` away: the body of "no pose yet" (the term 0, the kernel's shapes kept)."""
        ends = torch.full((count, 2, 3), FAR_M, device=device, dtype=dtype)
        ends[:, 1, 2] += 1.0
        return cls(ends, torch.zeros(count, device=device, dtype=dtype))


def body_clearances(centres: torch.Tensor, radii: torch.Tensor, body: BodyCapsules) -> torch.Tensor:
    """Each sphere's clearance to the body: its surface distance to the nearest capsule's surface.

    The costs take :func:`~services.planner.costs.hinge_sum` of ``body_clearance - clearance`` over the spheres (the
    obstacle term's hinge); the same measure as :func:`shared.clearance.sphere_capsule_clearance`, per sphere. The
    layout is the fused kernel's, the batch last (it vectorises along it; batch-first ran the term 3x slower).

    Args:
        centres: ``(3, S, ...)`` sphere centres: the coordinates first, then the S spheres, then any batch axes.
        radii: ``(S,)`` sphere radii.
        body: The capsules (C of them).

    Returns:
        ``(S, ...)`` metres, negative where a sphere overlaps a capsule.
    """
    extra = (1,) * (centres.ndim - 2)
    a = body.ends[:, 0].t().reshape(3, 1, -1, *extra)  # (3, 1, C, 1...)
    ab = (body.ends[:, 1] - body.ends[:, 0]).t().reshape(3, 1, -1, *extra)
    x = centres.unsqueeze(2) - a  # (3, S, C, ...)
    t = ((x * ab).sum(0) / (ab * ab).sum(0).clamp(min=1e-12)).clamp(0, 1)  # (S, C, ...)
    off = x - t * ab
    dist = (off * off).sum(0).clamp(min=1e-12).sqrt()  # centre to the capsule's axis
    return (dist - body.radii.reshape(1, -1, *extra)).amin(1) - radii.reshape(-1, *extra)


class PersonBody:
    """The newest pose's body, placed in the scene: what the planner service hands the planner (no Zenoh).

    The newest alone, not the guard's window of poses (see the module's docstring).

    The person stays where last seen until the next pose, as for the separation guard: a tracker's ``lost`` marker
    says where they are is unknown, and the last place seen is the nearest guess.

    Args:
        scene: The scene the person is placed in (``scene.human``, as the predictor and the guard place them).
        human: The human model (default: a new :class:`HumanModel`).

    Attributes:
        posture_: ``(12,)`` the newest pose's scene-frame posture (None before any).
        stamp_: Its stamp (s).
        poses_: Poses noted so far.
    """

    def __init__(self, scene, human: HumanModel | None = None) -> None:
        self.human = human or HumanModel()
        self.placement = StreamPlacement(scene)
        self.posture_: np.ndarray | None = None
        self.stamp_ = float("nan")
        self.poses_ = 0

    def note_pose(self, demo_id: int, index: int, features: np.ndarray, stamp: float) -> None:
        """The person's pose at ``stamp``: ``features`` ``(12,)``, the ``index``-th of demonstration ``demo_id``.

        Every pose must be noted (each demonstration is placed from its first), the newest one is kept.
        """
        self.posture_ = self.placement.place(demo_id, index, np.asarray(features, dtype=np.float64))
        self.stamp_ = float(stamp)
        self.poses_ += 1

    def capsules(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(ends (C, 2, 3), radii (C,))`` of the newest pose's body; None before any pose."""
        posture = self.posture_
        if posture is None:
            return None
        return self.human.capsules(posture)
