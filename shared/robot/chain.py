"""The PR2's planned serial chain (torso lift + right arm) folded into tables, and the fused FK kernels.

pytorch-kinematics parses the URDF and is the reference forward kinematics. :func:`fold_serial_chain`
folds its serial chain root -> tool frame into :class:`ChainTables` (one fixed offset per joint, fixed
joints merged), from which :func:`serial_fk` computes every link pose with one batched rotation per joint
written as a two-column update, and :func:`sphere_kernel` every collision sphere centre.
:meth:`ChainTables.transform_basis` writes each joint's local transform as a linear combination of
``1, cos q, sin q, q`` (what the planner's fused cost kernel builds its FK from).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytorch_kinematics as pk
import torch

from .files import RobotModelError

__all__ = ["JOINT_NAMES", "ROOT_FRAME", "TOOL_FRAME", "CONTINUOUS_RANGE", "JointStep", "ChainTables",
           "fold_serial_chain", "serial_fk", "sphere_kernel"]

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

JointStep = tuple[bool, int, float, bool, int, float]
"""Per joint ``(has_rotation_offset, axis index 0/1/2, axis sign, is_prismatic, offset kind, offset value)``;
offset kind: -2 no translation, 0/1/2 along that axis only (by ``offset value``), -1 general (``off_p``)."""


@dataclass(frozen=True)
class ChainTables:
    """The serial chain root -> tool frame as fixed offsets between joints (built once per model).

    Attributes:
        plan: J static :data:`JointStep` tuples, one per planned joint, in ``JOINT_NAMES`` order.
        off_r: ``(J, 3, 3)`` fixed rotation from the previous joint's link to each joint (model dtype).
        off_p: ``(J, 3)`` fixed translation from the previous joint's link to each joint.
        tool_p: ``(3,)`` tool frame offset from the last joint's link (no rotation).
        link_names: The L = J + 2 links whose poses :func:`serial_fk` returns: the root, each joint's
            child link, the tool frame.
    """

    plan: tuple[JointStep, ...]
    off_r: torch.Tensor
    off_p: torch.Tensor
    tool_p: torch.Tensor
    link_names: tuple[str, ...]

    def transform_basis(self, base_transform: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """Per joint j: ``H_j(q) = A0_j + cos(q) A1_j + sin(q) A2_j + q A3_j`` (4 x 4, float64).

        ``H_j`` is the transform from joint j - 1's link to joint j's link at joint value q (its fixed
        offset times the joint's motion); joint 0 includes the world-from-root ``base_transform`` (4, 4).

        Returns:
            ``(A0 (J, 16, 1), A123^T (J, 16, 3))`` float64 on the CPU.
        """
        d = len(self.plan)
        a = torch.zeros(d, 4, 4, 4, dtype=torch.float64)
        base = torch.as_tensor(base_transform, dtype=torch.float64)
        for j, (_, k, sign, prismatic, _, _) in enumerate(self.plan):
            off = torch.eye(4, dtype=torch.float64)
            off[:3, :3] = self.off_r[j].double().cpu()
            off[:3, 3] = self.off_p[j].double().cpu()
            if j == 0:
                off = base @ off
            axis = torch.zeros(3, dtype=torch.float64)
            axis[k] = sign
            if prismatic:
                t = torch.zeros(4, 4, dtype=torch.float64)
                t[:3, 3] = axis
                a[j, 0], a[j, 3] = off, off @ t
            else:  # Rodrigues: R = I + sin K + (1 - cos) K^2
                kx = torch.zeros(3, 3, dtype=torch.float64)
                kx[0, 1], kx[0, 2], kx[1, 0] = -axis[2], axis[1], axis[2]
                kx[1, 2], kx[2, 0], kx[2, 1] = -axis[0], -axis[1], axis[0]
                k2 = kx @ kx
                c0, c1, c2 = (torch.eye(4, dtype=torch.float64), torch.zeros(4, 4, dtype=torch.float64),
                              torch.zeros(4, 4, dtype=torch.float64))
                c0[:3, :3] += k2
                c1[:3, :3] = -k2
                c2[:3, :3] = kx
                a[j, 0], a[j, 1], a[j, 2] = off @ c0, off @ c1, off @ c2
        return a[:, 0].reshape(d, 16, 1), a[:, 1:].reshape(d, 3, 16).transpose(1, 2)


def fold_serial_chain(serial: pk.SerialChain, device: torch.device, dtype: torch.dtype) -> ChainTables:
    """Fold a pytorch-kinematics serial chain (float64, root -> tool frame) into :class:`ChainTables`.

    Raises:
        RobotModelError: A joint axis that is not a coordinate axis, or a rotated tool frame offset (the
            fused kernel supports neither).
    """
    path = serial.parents_indices[serial.frame_to_idx[TOOL_FRAME]].tolist()
    frames = [serial.find_frame(serial.idx_to_frame[i]) for i in path]
    eye = torch.eye(4, dtype=torch.float64)
    off_r, off_p, plan, link_names = [], [], [], [ROOT_FRAME]
    acc = eye
    for f in frames[1:]:
        lo_ = f.link.offset.get_matrix()[0] if f.link.offset is not None else eye
        jo_ = f.joint.offset.get_matrix()[0] if f.joint.offset is not None else eye
        acc = acc @ lo_.to(torch.float64) @ jo_.to(torch.float64)
        if f.joint.joint_type == "fixed":
            continue
        axis = f.joint.axis.to(torch.float64)
        k = int(torch.argmax(axis.abs()))
        if abs(abs(float(axis[k])) - 1.0) > 1e-9:
            raise RobotModelError(f"joint {f.joint.name}: axis {axis.tolist()} is not a coordinate axis; "
                                  "the fused kernel supports only those")
        has_rot = not torch.allclose(acc[:3, :3], eye[:3, :3], atol=1e-12)
        off_r.append(acc[:3, :3].clone())
        off_p.append(acc[:3, 3].clone())
        t_ = acc[:3, 3]
        nz = [i for i in range(3) if abs(float(t_[i])) > 1e-12]
        off_kind = -2 if not nz else nz[0] if len(nz) == 1 else -1
        plan.append((has_rot, k, float(axis[k]), f.joint.joint_type == "prismatic", off_kind,
                     float(t_[nz[0]]) if len(nz) == 1 else 0.0))
        link_names.append(f.name)
        acc = eye
    if not torch.allclose(acc[:3, :3], eye[:3, :3], atol=1e-12):
        raise RobotModelError("tool frame offset has a rotation; the fused kernel expects none")
    link_names.append(TOOL_FRAME)
    return ChainTables(tuple(plan), torch.stack(off_r).to(device, dtype), torch.stack(off_p).to(device, dtype),
                       acc[:3, 3].to(device, dtype), tuple(link_names))


def serial_fk(q: torch.Tensor, base_r: torch.Tensor, base_p: torch.Tensor, off_r: torch.Tensor,
              off_p: torch.Tensor, tool_p: torch.Tensor, plan: tuple[JointStep, ...]
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """Fused FK of a serial chain with coordinate-axis joints.

    Args:
        q: ``(B, J)`` joint values.
        base_r: ``(3, 3)`` world-from-root rotation.
        base_p: ``(3,)`` world-from-root translation.
        off_r: ``(J, 3, 3)`` :attr:`ChainTables.off_r`.
        off_p: ``(J, 3)`` :attr:`ChainTables.off_p`.
        tool_p: ``(3,)`` :attr:`ChainTables.tool_p`.
        plan: :attr:`ChainTables.plan` (static).

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


def sphere_kernel(q: torch.Tensor, base_r: torch.Tensor, base_p: torch.Tensor, off_r: torch.Tensor,
                  off_p: torch.Tensor, tool_p: torch.Tensor, weights: torch.Tensor,
                  plan: tuple[JointStep, ...]) -> torch.Tensor:
    """Sphere centres for a batch: fused FK then one contraction over links.

    Args:
        q: ``(B, J)`` joint values.
        base_r: See :func:`serial_fk`.
        base_p: See :func:`serial_fk`.
        off_r: See :func:`serial_fk`.
        off_p: See :func:`serial_fk`.
        tool_p: See :func:`serial_fk`.
        plan: See :func:`serial_fk`.
        weights: ``(L, 4, S)`` :attr:`shared.robot.spheres.SphereTables.weights`.

    Returns:
        ``(B, S, 3)`` world sphere centres.
    """
    rot, pos = serial_fk(q, base_r, base_p, off_r, off_p, tool_p, plan)
    t = torch.cat([rot, pos.unsqueeze(-1)], dim=-1)  # (B, L, 3, 4)
    return torch.einsum("blij,ljs->bsi", t, weights)
