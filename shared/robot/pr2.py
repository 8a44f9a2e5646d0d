"""The PR2 model for planning and execution: torso + right arm (D = 8), placed in the world.

:class:`PR2` loads the URDF and the sphere file (:mod:`shared.robot.files`), folds the planned chain
into :class:`~shared.robot.chain.ChainTables` and the spheres into
:class:`~shared.robot.spheres.SphereTables` (both public, for cost kernels), and evaluates link poses,
sphere centres, self-collision distances and limits; IK is in :mod:`shared.robot.ik`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytorch_kinematics as pk
import torch

from .chain import CONTINUOUS_RANGE, JOINT_NAMES, ROOT_FRAME, TOOL_FRAME, fold_serial_chain, serial_fk, sphere_kernel
from .files import RobotModelError, load_spheres, read_robot_file
from .ik import ik_batch, ik_solutions
from .spheres import build_sphere_tables

__all__ = ["PR2"]


class PR2:
    """PR2 torso + right arm (D = 8) with collision spheres, placed in the world.

    Args:
        device: Torch device of every tensor this model creates (``"cpu"``, ``"cuda"``).
        dtype: Float dtype (float32 by default).
        base_transform: ``(4, 4)`` world-from-``base_footprint``; identity when None.
        compile: Wrap the fused FK/sphere kernels in ``torch.compile`` (first call per shape compiles).
        urdf_path: Alternative URDF (default: the embedded ``pr2.urdf``).
        spheres_path: Alternative sphere file (default: the embedded ``pr2_spheres.toml``).

    Attributes:
        joint_names: The D planned joints, in order.
        lower, upper: ``(D,)`` position limits (continuous joints: ``CONTINUOUS_RANGE``).
        velocity_limits: ``(D,)`` |velocity| limits (m/s, rad/s).
        link_names: The L links returned by :meth:`fk_links` (root, each joint's child, tool frame).
        kinematics: :class:`~shared.robot.chain.ChainTables`, the folded chain (what FK kernels read).
        spheres: :class:`~shared.robot.spheres.SphereTables`, the collision spheres (what cost kernels read).
        sphere_radii: ``(S,)``; sphere_links: ``(S,)`` link names; sphere_anchor: ``(S,)`` index into
            ``link_names`` of the planned link each sphere moves with (the same as in ``spheres``).
        arm_spheres, body_spheres: index tensors of the self-collision groups (``arm_slice``,
            ``body_slice``: the same as slices; spheres are ordered so that groups are contiguous).
        moving_spheres: ``(S',)`` indices of spheres that move with q (all but the fixed base's),
            ``moving_slice`` the same as a slice; it is ``arm_carried_slice`` (spheres that depend on the
            arm joints) followed by ``torso_carried_slice`` (spheres that depend on the torso lift only).
        chain: pytorch-kinematics ``SerialChain`` root -> tool frame (reference FK).
        urdf_chain: pytorch-kinematics ``Chain`` of the whole robot (float64).
    """

    def __init__(self, device: str | torch.device = "cpu", dtype: torch.dtype = torch.float32,
                 base_transform: np.ndarray | None = None, *, compile: bool = False,
                 urdf_path: str | Path | None = None, spheres_path: str | Path | None = None) -> None:
        self.device = torch.device(device)
        self.dtype = dtype
        self.compiled = bool(compile)
        urdf_text, self.urdf_source = read_robot_file(urdf_path, "pr2.urdf")
        try:
            full = pk.build_chain_from_urdf(urdf_text.encode()).to(dtype=torch.float64)
        except Exception as exc:  # the parser raises many types
            raise RobotModelError(f"URDF {self.urdf_source}: cannot parse: {exc}") from None
        self.urdf_chain = full
        try:
            serial = pk.SerialChain(full, TOOL_FRAME, ROOT_FRAME, dtype=torch.float64)
        except Exception as exc:
            raise RobotModelError(f"URDF {self.urdf_source}: no chain {ROOT_FRAME} -> {TOOL_FRAME}: {exc}") from None
        names = serial.get_joint_parameter_names()
        if tuple(names) != JOINT_NAMES:
            raise RobotModelError(f"URDF {self.urdf_source}: chain joints {names} != expected {list(JOINT_NAMES)}")
        self.joint_names = list(JOINT_NAMES)
        self.dof = len(self.joint_names)

        # limits (continuous joints: finite documented range)
        lo, hi = serial.get_joint_limits()
        joints = serial.get_joints()
        lo, hi = list(lo), list(hi)
        self.continuous = []
        for i, jt in enumerate(joints):
            if jt.limits is None or (lo[i] == 0 and hi[i] == 0 and jt.joint_type == "revolute"):
                lo[i], hi[i] = CONTINUOUS_RANGE
                self.continuous.append(jt.name)
        _, vhi = serial.get_joint_velocity_limits()
        self.lower = torch.tensor(lo, device=self.device, dtype=dtype)
        self.upper = torch.tensor(hi, device=self.device, dtype=dtype)
        self.velocity_limits = torch.tensor(vhi, device=self.device, dtype=dtype)
        self._lower64, self._upper64 = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)

        self.kinematics = fold_serial_chain(serial, self.device, dtype)
        self.link_names = list(self.kinematics.link_names)
        self.chain = serial.to(dtype=dtype, device=str(self.device))
        self.set_base_transform(np.eye(4) if base_transform is None else base_transform)

        sph = load_spheres(spheres_path)
        self.sphere_source = sph["source"]
        self.posture = sph["posture"]
        t = self.spheres = build_sphere_tables(full, self.kinematics.link_names, sph, self.device, dtype)
        self.sphere_links = list(t.links)
        self.sphere_anchor, self.sphere_radii = t.anchor, t.radii
        self.arm_slice, self.body_slice, self.moving_slice = t.arm, t.body, t.moving
        self.arm_carried_slice, self.torso_carried_slice = t.arm_carried, t.torso_carried
        index = torch.arange(len(t.links), device=self.device)
        self.arm_spheres, self.body_spheres, self.moving_spheres = index[t.arm], index[t.body], index[t.moving]
        self._sphere_fn: Callable[..., torch.Tensor] = sphere_kernel
        self._fk_fn: Callable[..., tuple[torch.Tensor, torch.Tensor]] = serial_fk
        if self.compiled:
            self._sphere_fn = torch.compile(sphere_kernel)
            self._fk_fn = torch.compile(serial_fk)
        self._arm_chain: pk.SerialChain | None = None
        self.q_start: torch.Tensor | None = None

    # ------------------------------------------------------------------------------------------
    # construction helpers

    @classmethod
    def from_scene(cls, scene: Any, device: str | torch.device = "cpu", dtype: torch.dtype = torch.float32,
                   **kwargs: Any) -> PR2:
        """PR2 at ``scene.robot``'s base pose; ``q_start`` = (torso lift, start arm) when the scene has one."""
        robot = cls(device=device, dtype=dtype, base_transform=scene.robot.base_transform(), **kwargs)
        arm = getattr(scene.robot, "start_arm", None)
        if arm is not None:
            q0 = np.concatenate([[scene.robot.torso_lift], np.asarray(arm, dtype=np.float64)])
            robot.q_start = robot.validate_configuration(q0, what=f"scene {scene.name}: robot start")
        else:
            robot.validate_torso_lift(scene.robot.torso_lift, what=f"scene {scene.name}: robot.torso_lift")
        return robot

    def set_base_transform(self, base_transform: np.ndarray) -> None:
        """Place the robot: ``base_transform`` ``(4, 4)`` world-from-``base_footprint``."""
        t = np.asarray(base_transform, dtype=np.float64)
        if t.shape != (4, 4) or not np.all(np.isfinite(t)):
            raise RobotModelError(f"base_transform must be a finite (4, 4) matrix, got shape {t.shape}")
        if not np.allclose(t[:3, :3] @ t[:3, :3].T, np.eye(3), atol=1e-6):
            raise RobotModelError("base_transform rotation is not orthonormal")
        self.base_transform = t
        self._base_r = torch.tensor(t[:3, :3], device=self.device, dtype=self.dtype)
        self._base_p = torch.tensor(t[:3, 3], device=self.device, dtype=self.dtype)

    # ------------------------------------------------------------------------------------------
    # kinematics (hot path)

    def _flat(self, q: torch.Tensor) -> tuple[torch.Tensor, tuple[int, ...]]:
        if q.shape[-1] != self.dof:
            raise RobotModelError(f"q must have last dimension {self.dof} ({self.joint_names}), got {tuple(q.shape)}")
        lead = tuple(q.shape[:-1])
        return q.reshape(-1, self.dof).to(self.dtype), lead

    def fk_links(self, q: torch.Tensor) -> torch.Tensor:
        """World poses of the chain's links (fused kernel).

        Args:
            q: ``(..., D)`` joint values.

        Returns:
            ``(..., L, 4, 4)`` world-from-link transforms, links in ``link_names`` order.
        """
        qf, lead = self._flat(q)
        k = self.kinematics
        rot, pos = self._fk_fn(qf, self._base_r, self._base_p, k.off_r, k.off_p, k.tool_p, k.plan)
        out = torch.zeros(qf.shape[0], rot.shape[1], 4, 4, device=qf.device, dtype=qf.dtype)
        out[..., :3, :3] = rot
        out[..., :3, 3] = pos
        out[..., 3, 3] = 1.0
        return out.reshape(*lead, rot.shape[1], 4, 4)

    def sphere_centers(self, q: torch.Tensor) -> torch.Tensor:
        """World positions of the collision spheres.

        Args:
            q: ``(..., D)`` joint values.

        Returns:
            ``(..., S, 3)`` sphere centres (radii: ``sphere_radii``).
        """
        qf, lead = self._flat(q)
        k = self.kinematics
        c = self._sphere_fn(qf, self._base_r, self._base_p, k.off_r, k.off_p, k.tool_p, self.spheres.weights, k.plan)
        return c.reshape(*lead, c.shape[-2], 3)

    def end_effector(self, q: torch.Tensor) -> torch.Tensor:
        """World pose of the gripper tool frame: ``q`` ``(..., D)`` -> ``(..., 4, 4)``."""
        return self.fk_links(q)[..., -1, :, :]

    def fk_reference(self, q: torch.Tensor) -> torch.Tensor:
        """pytorch-kinematics ``forward_kinematics_tensor`` of the same links (slow reference).

        Args:
            q: ``(..., D)``.

        Returns:
            ``(..., L, 4, 4)`` world poses in ``link_names`` order.
        """
        qf, lead = self._flat(q)
        all_t = self.chain.forward_kinematics_tensor(qf)  # (F, B, 4, 4) root frame
        idx = [self.chain.frame_to_idx[n] for n in self.link_names]
        t = all_t[idx].permute(1, 0, 2, 3)
        base = torch.tensor(self.base_transform, device=qf.device, dtype=qf.dtype)
        return (base @ t).reshape(*lead, len(idx), 4, 4)

    def self_collision_distance(self, centers: torch.Tensor) -> torch.Tensor:
        """Signed surface distance between every arm sphere and every body sphere.

        Args:
            centers: ``(..., S, 3)`` from :meth:`sphere_centers`.

        Returns:
            ``(..., A, B)`` distances (m), negative where the spheres overlap.
        """
        a = centers[..., self.arm_slice, :]
        b = centers[..., self.body_slice, :]
        d2 = ((a * a).sum(-1).unsqueeze(-1) + (b * b).sum(-1).unsqueeze(-2)
              - 2.0 * torch.matmul(a, b.transpose(-1, -2)))
        return torch.sqrt(d2.clamp(min=1e-12)) - self.spheres.pair_radii

    # ------------------------------------------------------------------------------------------
    # limits and validation

    def within_limits(self, q: torch.Tensor, tol: float = 1e-6) -> torch.Tensor:
        """``q`` ``(..., D)`` -> ``(...)`` bool, true where every joint is within its limits (+- tol)."""
        return ((q >= self.lower - tol) & (q <= self.upper + tol)).all(dim=-1)

    def validate_configuration(self, q: Any, what: str = "configuration") -> torch.Tensor:
        """Check one configuration and return it as a ``(D,)`` tensor on the model's device.

        Raises:
            RobotModelError: Wrong shape, non-finite values, or a joint outside its limits (named).
        """
        arr = np.asarray(q.detach().cpu().numpy() if torch.is_tensor(q) else q, dtype=np.float64)
        if arr.shape != (self.dof,):
            raise RobotModelError(f"{what}: expected {self.dof} joint values {self.joint_names}, "
                                  f"got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise RobotModelError(f"{what}: non-finite joint values {arr.tolist()}")
        bad = [(n, float(v), float(lo), float(hi)) for n, v, lo, hi
               in zip(self.joint_names, arr, self._lower64, self._upper64, strict=True)
               if v < lo - 1e-6 or v > hi + 1e-6]
        if bad:
            msg = ", ".join(f"{n}={v:.4f} not in [{lo:.4f}, {hi:.4f}]" for n, v, lo, hi in bad)
            raise RobotModelError(f"{what}: outside joint limits: {msg}")
        return torch.tensor(arr, device=self.device, dtype=self.dtype)

    def validate_torso_lift(self, lift: float, what: str = "torso lift") -> None:
        """Raise :class:`RobotModelError` unless ``lift`` (m) lies within the torso joint's limits."""
        if not (self._lower64[0] <= lift <= self._upper64[0]):
            raise RobotModelError(f"{what} {lift} outside [{self._lower64[0]}, {self._upper64[0]}]")

    # ------------------------------------------------------------------------------------------
    # inverse kinematics (shared.robot.ik)

    def arm_chain(self) -> pk.SerialChain:
        """pytorch-kinematics chain ``torso_lift_link`` -> tool frame with the model's finite arm limits."""
        if self._arm_chain is None:
            ch = pk.SerialChain(self.urdf_chain, TOOL_FRAME, "torso_lift_link", dtype=torch.float64)
            ch = ch.to(dtype=self.dtype, device=str(self.device))
            ch.low = self.lower[1:].clone()
            ch.high = self.upper[1:].clone()
            self._arm_chain = ch
        return self._arm_chain

    def ik_solutions(self, targets: np.ndarray | torch.Tensor, q_seed: Any, **kwargs: Any
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Arm IK for M targets ``(M, 4, 4)`` from N seeds each: :func:`shared.robot.ik.ik_solutions`."""
        return ik_solutions(self, targets, q_seed, **kwargs)

    def ik_batch(self, targets: np.ndarray | torch.Tensor, q_seed: Any, **kwargs: Any
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Per target the converged solution closest to ``q_seed``: :func:`shared.robot.ik.ik_batch`."""
        return ik_batch(self, targets, q_seed, **kwargs)

    def ik(self, target: np.ndarray, q_seed: Any, **kwargs: Any) -> tuple[torch.Tensor, bool]:
        """IK for one world target ``(4, 4)`` -> ``(q (D,), ok)``; ``q`` is always within the limits."""
        t = np.asarray(target, dtype=np.float64)
        if t.shape != (4, 4):
            raise RobotModelError(f"IK target must be (4, 4), got {t.shape}")
        q, ok, _, _ = ik_batch(self, t[None], q_seed, **kwargs)
        return q[0], bool(ok[0])
