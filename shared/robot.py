"""PR2 model for planning and execution: torso + right arm kinematics, collision spheres, IK.

The robot is described by the repo's own URDF (``shared/data/robot/pr2.urdf``) and sphere file
(``shared/data/robot/pr2_spheres.toml``). pytorch-kinematics parses the URDF, builds the chain and
is the reference forward kinematics and the IK solver. The planner's hot path uses a fused
serial-chain kernel derived from pytorch-kinematics' parsed chain (fixed offsets folded, one
batched rotation per joint written as a two-column update) that is tested equal to
``forward_kinematics_tensor``.

Planned joints (D = 8, in this order): ``torso_lift_joint`` and the seven right-arm joints. The head,
the tucked left arm and the fingers are held at the sphere file's ``[posture]``; their spheres move
rigidly with their nearest planned ancestor link. The base is fixed in the world at
``base_transform`` (world-from-``base_footprint``).

Continuous joints (``r_forearm_roll_joint``, ``r_wrist_roll_joint``) have no URDF limits; this model
gives them the finite range ``CONTINUOUS_RANGE`` = [-pi, pi] (pytorch-kinematics would report (0, 0)).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytorch_kinematics as pk
import torch

__all__ = ["PR2", "RobotModelError", "JOINT_NAMES", "CONTINUOUS_RANGE", "TOOL_FRAME", "ROOT_FRAME",
           "load_spheres"]

JOINT_NAMES: tuple[str, ...] = (
    "torso_lift_joint",
    "r_shoulder_pan_joint",
    "r_shoulder_lift_joint",
    "r_upper_arm_roll_joint",
    "r_elbow_flex_joint",
    "r_forearm_roll_joint",
    "r_wrist_flex_joint",
    "r_wrist_roll_joint",
)
ROOT_FRAME = "base_footprint"
TOOL_FRAME = "r_gripper_tool_frame"
CONTINUOUS_RANGE = (-math.pi, math.pi)


class RobotModelError(ValueError):
    """Bad robot model file, bad configuration (shape, NaN, outside limits) or bad IK target."""


def _data_text(name: str) -> tuple[str, str]:
    res = resources.files("shared") / "data" / "robot" / name
    if not res.is_file():
        raise RobotModelError(f"robot data file {name!r} missing from the package")
    return res.read_text(), f"shared/data/robot/{name}"


def _read(path: str | Path | None, default: str) -> tuple[str, str]:
    if path is None:
        return _data_text(default)
    p = Path(path)
    if not p.is_file():
        raise RobotModelError(f"robot file {str(p)!r} not found")
    return p.read_text(), str(p)


def load_spheres(path: str | Path | None = None) -> dict[str, Any]:
    """Read and validate the sphere file.

    Returns:
        ``{"posture": {joint: value}, "spheres": {link: (n, 4) array}, "groups": {name: [links]}}``.

    Raises:
        RobotModelError: Missing file, bad TOML or a malformed entry (named in the message).
    """
    text, source = _read(path, "pr2_spheres.toml")
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


def _quiet_build_chain(urdf_text: str) -> pk.Chain:
    return pk.build_chain_from_urdf(urdf_text.encode())


# ----------------------------------------------------------------------------------------------
# the fused serial-chain kernel


def _serial_fk(q: torch.Tensor, base_r: torch.Tensor, base_p: torch.Tensor, off_r: torch.Tensor,
               off_p: torch.Tensor, tool_p: torch.Tensor, plan: tuple[tuple[bool, int, float, bool, int, float], ...]
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """Fused FK of a serial chain with coordinate-axis joints.

    Args:
        q: ``(B, J)`` joint values.
        base_r: ``(3, 3)`` world-from-root rotation.
        base_p: ``(3,)`` world-from-root translation.
        off_r: ``(J, 3, 3)`` fixed rotation from the previous joint's link to each joint.
        off_p: ``(J, 3)`` fixed translation from the previous joint's link to each joint.
        tool_p: ``(3,)`` tool frame offset from the last joint's link (no rotation).
        plan: Per joint ``(has_rotation_offset, axis index 0/1/2, axis sign, is_prismatic, offset kind,
            offset value)`` (static); offset kind: -2 no translation, 0/1/2 along that axis only (by
            ``offset value``), -1 general (``off_p``).

    Returns:
        ``(R, p)``: ``(B, J + 2, 3, 3)`` and ``(B, J + 2, 3)`` world rotations and positions of the root,
        each joint's child link, and the tool frame.
    """
    b = q.shape[0]
    r = base_r.expand(b, 3, 3)
    p = base_p.expand(b, 3)
    rs, ps = [r], [p]
    for j, (has_rot, k, sign, prismatic, off_axis, off_val) in enumerate(plan):
        if off_axis == -1:  # general offset
            p = p + r @ off_p[j]
        elif off_axis >= 0:  # offset along one axis of the parent link: one column, no matmul
            p = p + r[:, :, off_axis] * off_val
        if has_rot:
            r = r @ off_r[j]
        if prismatic:
            p = p + r[:, :, k] * (sign * q[:, j : j + 1])
        else:
            th = q[:, j : j + 1] * sign
            c, s = torch.cos(th), torch.sin(th)
            a, bb = (k + 1) % 3, (k + 2) % 3
            ca, cb = r[:, :, a], r[:, :, bb]
            cols = [r[:, :, 0], r[:, :, 1], r[:, :, 2]]
            cols[a] = c * ca + s * cb
            cols[bb] = c * cb - s * ca
            r = torch.stack(cols, dim=-1)
        rs.append(r)
        ps.append(p)
    ps.append(p + r @ tool_p)
    rs.append(r)
    return torch.stack(rs, dim=1), torch.stack(ps, dim=1)


def _sphere_kernel(q: torch.Tensor, base_r: torch.Tensor, base_p: torch.Tensor, off_r: torch.Tensor,
                   off_p: torch.Tensor, tool_p: torch.Tensor, weights: torch.Tensor,
                   plan: tuple[tuple[bool, int, float, bool, int, float], ...]) -> torch.Tensor:
    """Sphere centres for a batch: fused FK then one contraction over links.

    Args:
        q: ``(B, J)`` joint values.
        base_r: See :func:`_serial_fk`.
        base_p: See :func:`_serial_fk`.
        off_r: See :func:`_serial_fk`.
        off_p: See :func:`_serial_fk`.
        tool_p: See :func:`_serial_fk`.
        plan: See :func:`_serial_fk`.
        weights: ``(L, 4, S)`` homogeneous local centre of each sphere in its anchor link's column
            block (zero elsewhere), so that ``centre_s = sum_l [R_l | p_l] @ weights[l, :, s]``.

    Returns:
        ``(B, S, 3)`` world sphere centres.
    """
    rot, pos = _serial_fk(q, base_r, base_p, off_r, off_p, tool_p, plan)
    t = torch.cat([rot, pos.unsqueeze(-1)], dim=-1)  # (B, L, 3, 4)
    return torch.einsum("blij,ljs->bsi", t, weights)


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
        sphere_radii: ``(S,)``; sphere_links: ``(S,)`` link names; sphere_anchor: ``(S,)`` index into
            ``link_names`` of the planned link each sphere moves with.
        arm_spheres, body_spheres: index tensors of the self-collision groups (``arm_slice``,
            ``body_slice``: the same as slices; spheres are ordered so that groups are contiguous).
        moving_spheres: ``(S',)`` indices of spheres that move with q (all but the fixed base's),
            ``moving_slice`` the same as a slice; it is ``arm_carried_slice`` (spheres that depend on the
            arm joints) followed by ``torso_carried_slice`` (spheres that depend on the torso lift only).
        chain: pytorch-kinematics ``SerialChain`` root -> tool frame (reference FK).
    """

    def __init__(self, device: str | torch.device = "cpu", dtype: torch.dtype = torch.float32,
                 base_transform: np.ndarray | None = None, *, compile: bool = False,
                 urdf_path: str | Path | None = None, spheres_path: str | Path | None = None) -> None:
        self.device = torch.device(device)
        self.dtype = dtype
        self.compiled = bool(compile)
        urdf_text, self.urdf_source = _read(urdf_path, "pr2.urdf")
        try:
            full = _quiet_build_chain(urdf_text).to(dtype=torch.float64)
        except Exception as exc:  # the parser raises many types
            raise RobotModelError(f"URDF {self.urdf_source}: cannot parse: {exc}") from None
        self._full = full
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

        # fold pytorch-kinematics' serial frames into (fixed offset, joint) pairs
        off_r, off_p, plan, self.link_names = [], [], [], [ROOT_FRAME]
        acc = torch.eye(4, dtype=torch.float64)
        frames = serial._serial_frames
        tool_acc = None
        for f in frames[1:]:
            lo_ = f.link.offset.get_matrix()[0] if f.link.offset is not None else torch.eye(4, dtype=torch.float64)
            jo_ = f.joint.offset.get_matrix()[0] if f.joint.offset is not None else torch.eye(4, dtype=torch.float64)
            acc = acc @ lo_.to(torch.float64) @ jo_.to(torch.float64)
            if f.joint.joint_type == "fixed":
                continue
            axis = f.joint.axis.to(torch.float64)
            k = int(torch.argmax(axis.abs()))
            if abs(abs(float(axis[k])) - 1.0) > 1e-9:
                raise RobotModelError(f"joint {f.joint.name}: axis {axis.tolist()} is not a coordinate axis; "
                                      "the fused kernel supports only those")
            has_rot = not torch.allclose(acc[:3, :3], torch.eye(3, dtype=torch.float64), atol=1e-12)
            off_r.append(acc[:3, :3].clone())
            off_p.append(acc[:3, 3].clone())
            t_ = acc[:3, 3]
            nz = [i for i in range(3) if abs(float(t_[i])) > 1e-12]
            off_kind = -2 if not nz else nz[0] if len(nz) == 1 else -1
            plan.append((has_rot, k, float(axis[k]), f.joint.joint_type == "prismatic", off_kind,
                         float(t_[nz[0]]) if len(nz) == 1 else 0.0))
            self.link_names.append(f.name)
            acc = torch.eye(4, dtype=torch.float64)
        tool_acc = acc
        if not torch.allclose(tool_acc[:3, :3], torch.eye(3, dtype=torch.float64), atol=1e-12):
            raise RobotModelError("tool frame offset has a rotation; the fused kernel expects none")
        self.link_names.append(TOOL_FRAME)
        self._plan = tuple(plan)
        self._off_r = torch.stack(off_r).to(self.device, dtype)
        self._off_p = torch.stack(off_p).to(self.device, dtype)
        self._tool_p = tool_acc[:3, 3].to(self.device, dtype)
        self.chain = serial.to(dtype=dtype, device=str(self.device))
        self._frame_index = {n: i for i, n in enumerate(self.link_names)}
        self.set_base_transform(np.eye(4) if base_transform is None else base_transform)

        # spheres: attach each sphere link to its nearest planned ancestor at the held posture
        sph = load_spheres(spheres_path)
        self.sphere_source = sph["source"]
        self.posture = sph["posture"]
        unknown = [j for j in self.posture if j not in full.get_joint_parameter_names()]
        if unknown:
            raise RobotModelError(f"{self.sphere_source}: posture names unknown joints {unknown}")
        rows_ = []
        t_world = self._posture_fk()
        groups = sph["groups"]
        arm_links, body_links = set(groups.get("arm", [])), set(groups.get("body", []))
        for link, rows in sph["spheres"].items():
            anchor = self._frame_index[self._anchor_of(link)]
            t_al = np.linalg.inv(t_world[self.link_names[anchor]]) @ t_world[link]
            # order: carried by the arm joints (non-arm group, then arm group), carried by the torso only
            # (non-body, then body), fixed base (body, then non-body) -> every group is a contiguous slice
            if anchor >= 2:
                rank = 1 if link in arm_links else 0
            elif anchor == 1:
                rank = 3 if link in body_links else 2
            else:
                rank = 4 if link in body_links else 5
            for x, y, z, rad in rows:
                rows_.append((rank, anchor, t_al[:3, :3] @ np.array([x, y, z]) + t_al[:3, 3], rad, link))
        rows_.sort(key=lambda r_: r_[0])  # stable: file order within a rank
        anchors = [r_[1] for r_ in rows_]
        locals_ = [r_[2] for r_ in rows_]
        links = [r_[4] for r_ in rows_]
        self.sphere_links = links
        self.sphere_anchor = torch.tensor(anchors, device=self.device, dtype=torch.long)
        self._sphere_local = torch.tensor(np.asarray(locals_), device=self.device, dtype=dtype)
        w = torch.zeros(len(self.link_names), 4, len(links), dtype=dtype)
        for s_, (a_, c_) in enumerate(zip(anchors, locals_, strict=True)):
            w[a_, :3, s_] = torch.tensor(c_, dtype=dtype)
            w[a_, 3, s_] = 1.0
        self._sphere_weights = w.to(self.device)
        self.sphere_radii = torch.tensor([r_[3] for r_ in rows_], device=self.device, dtype=dtype)

        def _slice(sel: list[int]) -> slice:
            if not sel:
                return slice(0, 0)
            if sel != list(range(sel[0], sel[-1] + 1)):
                raise RobotModelError(f"{self.sphere_source}: the body group must hold every fixed-base link "
                                      "(groups must be contiguous after ordering)")
            return slice(sel[0], sel[-1] + 1)

        self.arm_slice = _slice([i for i, ln in enumerate(links) if ln in arm_links])
        self.body_slice = _slice([i for i, ln in enumerate(links) if ln in body_links])
        self.moving_slice = _slice([i for i, a in enumerate(anchors) if a != 0])
        self.arm_carried_slice = _slice([i for i, a in enumerate(anchors) if a >= 2])
        self.torso_carried_slice = _slice([i for i, a in enumerate(anchors) if a == 1])
        self.arm_spheres = torch.arange(len(links), device=self.device)[self.arm_slice]
        self.body_spheres = torch.arange(len(links), device=self.device)[self.body_slice]
        self.moving_spheres = torch.arange(len(links), device=self.device)[self.moving_slice]
        self._pair_radii = (self.sphere_radii[self.arm_slice][:, None] + self.sphere_radii[self.body_slice][None, :])
        self._sphere_fn: Callable[..., torch.Tensor] = _sphere_kernel
        self._fk_fn: Callable[..., tuple[torch.Tensor, torch.Tensor]] = _serial_fk
        if self.compiled:
            self._sphere_fn = torch.compile(_sphere_kernel)
            self._fk_fn = torch.compile(_serial_fk)
        self._ik_chain = None
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
            if not (robot._lower64[0] <= scene.robot.torso_lift <= robot._upper64[0]):
                raise RobotModelError(f"scene {scene.name}: robot.torso_lift {scene.robot.torso_lift} outside "
                                      f"[{robot._lower64[0]}, {robot._upper64[0]}]")
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

    def _posture_fk(self) -> dict[str, np.ndarray]:
        """Root-frame poses (float64) of every frame at zero planned joints and the held posture."""
        names = self._full.get_joint_parameter_names()
        th = torch.tensor([[self.posture.get(n, 0.0) for n in names]], dtype=torch.float64)
        out = self._full.forward_kinematics(th)
        return {k: v.get_matrix()[0].numpy() for k, v in out.items()}

    def _anchor_of(self, link: str) -> str:
        frame = self._full.find_frame(link)
        if frame is None:
            raise RobotModelError(f"{self.sphere_source}: spheres for unknown link {link!r}")
        path = self._full.parents_indices[self._full.frame_to_idx[link]].tolist()
        for idx in reversed(path):
            name = self._full.idx_to_frame[idx]
            if name in self._frame_index and name != TOOL_FRAME:
                return name
        raise RobotModelError(f"link {link!r} is not below {ROOT_FRAME}")

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
        rot, pos = self._fk_fn(qf, self._base_r, self._base_p, self._off_r, self._off_p, self._tool_p, self._plan)
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
        c = self._sphere_fn(qf, self._base_r, self._base_p, self._off_r, self._off_p, self._tool_p,
                            self._sphere_weights, self._plan)
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
        return torch.sqrt(d2.clamp(min=1e-12)) - self._pair_radii

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

    # ------------------------------------------------------------------------------------------
    # inverse kinematics

    def _arm_ik_chain(self) -> pk.SerialChain:
        if self._ik_chain is None:
            ch = pk.SerialChain(self._full, TOOL_FRAME, "torso_lift_link", dtype=torch.float64)
            ch = ch.to(dtype=self.dtype, device=str(self.device))
            ch.low = self.lower[1:].clone()
            ch.high = self.upper[1:].clone()
            self._ik_chain = ch
        return self._ik_chain

    def ik_solutions(self, targets: np.ndarray | torch.Tensor, q_seed: Any, n_seeds: int = 24, seed: int = 0,
                     pos_tolerance: float = 2e-3, rot_tolerance: float = 2e-2, max_iterations: int = 80
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Arm IK for M world targets from N seeds each, the torso held at ``q_seed``'s lift.

        Seeds: ``q_seed``'s arm plus ``n_seeds - 1`` uniform samples within the limits (deterministic
        from ``seed``). pytorch-kinematics' damped least-squares IK (``PseudoInverseIK``) on the
        torso -> tool chain with the model's finite limits (clamped every step).

        Args:
            targets: ``(M, 4, 4)`` world-from-tool targets.
            q_seed: ``(D,)`` configuration (its torso lift is kept).
            n_seeds: Initial configurations per target (the first is ``q_seed``).
            seed: Seed of the random initial configurations.
            pos_tolerance: Position tolerance of convergence (m).
            rot_tolerance: Rotation tolerance of convergence (rad).
            max_iterations: Damped least-squares iterations.

        Returns:
            ``(q, ok, pos_err, rot_err)``: ``(M, N, D)`` solutions (clamped within the limits),
            ``(M, N)`` bool converged and within limits, ``(M, N)`` position (m) and rotation (rad) errors.

        Raises:
            RobotModelError: Bad seed (shape, NaN, outside the limits) or targets not finite ``(M, 4, 4)``.
        """
        q0 = self.validate_configuration(q_seed, what="IK seed")
        tw = torch.as_tensor(np.asarray(targets, dtype=np.float64) if not torch.is_tensor(targets)
                             else targets.detach().cpu().numpy(), dtype=torch.float64)
        if tw.ndim != 3 or tw.shape[1:] != (4, 4) or not torch.isfinite(tw).all():
            raise RobotModelError(f"IK targets must be finite (M, 4, 4), got {tuple(tw.shape)}")
        # world -> torso_lift_link frame at the seed's lift
        t_torso = self.fk_links(q0.unsqueeze(0))[0, 1].double().cpu()  # world-from-torso_lift_link
        local = torch.linalg.inv(t_torso) @ tw
        ch = self._arm_ik_chain()
        gen = torch.Generator().manual_seed(seed)
        lo, hi = self.lower[1:].cpu(), self.upper[1:].cpu()
        rand = lo + (hi - lo) * torch.rand(max(n_seeds - 1, 0), self.dof - 1, generator=gen, dtype=self.dtype)
        seeds = torch.cat([q0[1:].cpu().unsqueeze(0), rand]).to(self.device, self.dtype)
        solver = pk.PseudoInverseIK(ch, pos_tolerance=pos_tolerance, rot_tolerance=rot_tolerance,
                                    retry_configs=seeds, joint_limits=torch.stack([ch.low, ch.high], -1),
                                    max_iterations=max_iterations, early_stopping_no_improvement=None,
                                    lr=0.5, clamp_to_limits=True)
        sol = solver.solve(pk.Transform3d(matrix=local.to(self.device, self.dtype)))
        qa = sol.solutions  # (M, N, 7)
        full = torch.cat([q0[0].expand(*qa.shape[:2], 1), qa], dim=-1)
        inside = self.within_limits(full)
        full = torch.minimum(torch.maximum(full, self.lower), self.upper)
        return full, sol.converged & inside, sol.err_pos, sol.err_rot

    def ik_batch(self, targets: np.ndarray | torch.Tensor, q_seed: Any, **kwargs: Any
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Like :meth:`ik_solutions`, keeping per target the converged solution closest to ``q_seed``.

        Returns:
            ``(q, ok, pos_err, rot_err)``: ``(M, D)`` (within the limits), ``(M,)`` bool, ``(M,)``, ``(M,)``.
        """
        q, good, ep, er = self.ik_solutions(targets, q_seed, **kwargs)
        q0 = self.validate_configuration(q_seed, what="IK seed")
        dist = (q - q0).abs().sum(-1)
        score = torch.where(good, dist, dist + 1e6 + (ep + er) * 1e3)
        best = score.argmin(dim=1)
        ar = torch.arange(q.shape[0], device=q.device)
        return q[ar, best], good[ar, best], ep[ar, best], er[ar, best]

    def ik(self, target: np.ndarray, q_seed: Any, **kwargs: Any) -> tuple[torch.Tensor, bool]:
        """IK for one world target ``(4, 4)`` -> ``(q (D,), ok)``; ``q`` is always within the limits."""
        t = np.asarray(target, dtype=np.float64)
        if t.shape != (4, 4):
            raise RobotModelError(f"IK target must be (4, 4), got {t.shape}")
        q, ok, _, _ = self.ik_batch(t[None], q_seed, **kwargs)
        return q[0], bool(ok[0])
