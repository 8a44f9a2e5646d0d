"""The PR2's collision spheres as tables: each sphere's link, local centre, radius and self-collision group.

Every sphere of the sphere file moves rigidly with its nearest *planned* ancestor link (its anchor: the
root, the torso lift link or one of the right arm's links) at the file's held ``[posture]`` of the
head, the tucked left arm and the fingers. The spheres are ordered so that every group the costs
need is one contiguous slice: carried by the arm joints (non-arm group, then the arm group), carried by
the torso lift only (non-body, then body), fixed with the base (body, then non-body).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytorch_kinematics as pk
import torch

from .chain import TOOL_FRAME
from .files import RobotModelError

__all__ = ["SphereTables", "build_sphere_tables"]


@dataclass(frozen=True)
class SphereTables:
    """The S collision spheres of the model (built once per model, model device and dtype).

    Attributes:
        links: S link names (the sphere file's link of each sphere).
        anchor: ``(S,)`` long index into ``ChainTables.link_names`` of the planned link each sphere moves with.
        local: ``(S, 3)`` sphere centres in their anchor link's frame.
        weights: ``(L, 4, S)`` homogeneous local centre of each sphere in its anchor link's column block (zero
            elsewhere), so that ``centre_s = sum_l [R_l | p_l] @ weights[l, :, s]`` over the L link poses.
        radii: ``(S,)`` radii (m).
        pair_radii: ``(A, B)`` radius sums of every arm-group sphere with every body-group sphere.
        arm, body: Slices of the self-collision groups (arm spheres are checked against body spheres).
        moving: Slice of the spheres that move with q (all but the fixed base's): ``arm_carried`` (they
            depend on the arm joints) followed by ``torso_carried`` (they depend on the torso lift only).
        arm_carried, torso_carried: See ``moving``.
    """

    links: tuple[str, ...]
    anchor: torch.Tensor
    local: torch.Tensor
    weights: torch.Tensor
    radii: torch.Tensor
    pair_radii: torch.Tensor
    arm: slice
    body: slice
    moving: slice
    arm_carried: slice
    torso_carried: slice


def _posture_poses(full: pk.Chain, posture: dict[str, float]) -> dict[str, np.ndarray]:
    """Root-frame poses (float64) of every frame at zero planned joints and the held posture."""
    names = full.get_joint_parameter_names()
    th = torch.tensor([[posture.get(n, 0.0) for n in names]], dtype=torch.float64)
    out = full.forward_kinematics(th)
    return {k: v.get_matrix()[0].numpy() for k, v in out.items()}


def _anchor_of(full: pk.Chain, link: str, link_names: tuple[str, ...], source: str) -> int:
    """Index in ``link_names`` of the nearest planned ancestor of ``link`` (not the tool frame)."""
    if full.find_frame(link) is None:
        raise RobotModelError(f"{source}: spheres for unknown link {link!r}")
    path = full.parents_indices[full.frame_to_idx[link]].tolist()
    for idx in reversed(path):
        name = full.idx_to_frame[idx]
        if name in link_names and name != TOOL_FRAME:
            return link_names.index(name)
    raise RobotModelError(f"link {link!r} is not below {link_names[0]}")


def build_sphere_tables(full: pk.Chain, link_names: tuple[str, ...], sph: dict[str, Any],
                        device: torch.device, dtype: torch.dtype) -> SphereTables:
    """Attach the sphere file's spheres to the planned links.

    Args:
        full: The whole robot's pytorch-kinematics chain (float64), for the posture and the link tree.
        link_names: ``ChainTables.link_names``.
        sph: :func:`shared.robot.files.load_spheres` output.
        device: Device of the tables.
        dtype: Float dtype of the tables.

    Raises:
        RobotModelError: The posture names unknown joints, a sphere's link is unknown, or the groups are
            not contiguous after ordering.
    """
    source = sph["source"]
    unknown = [j for j in sph["posture"] if j not in full.get_joint_parameter_names()]
    if unknown:
        raise RobotModelError(f"{source}: posture names unknown joints {unknown}")
    t_world = _posture_poses(full, sph["posture"])
    arm_links, body_links = set(sph["groups"].get("arm", [])), set(sph["groups"].get("body", []))
    rows_ = []
    for link, rows in sph["spheres"].items():
        anchor = _anchor_of(full, link, link_names, source)
        t_al = np.linalg.inv(t_world[link_names[anchor]]) @ t_world[link]
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
    w = torch.zeros(len(link_names), 4, len(links), dtype=dtype)
    for s_, (a_, c_) in enumerate(zip(anchors, locals_, strict=True)):
        w[a_, :3, s_] = torch.tensor(c_, dtype=dtype)
        w[a_, 3, s_] = 1.0
    radii = torch.tensor([r_[3] for r_ in rows_], device=device, dtype=dtype)

    def _slice(sel: list[int]) -> slice:
        if not sel:
            return slice(0, 0)
        if sel != list(range(sel[0], sel[-1] + 1)):
            raise RobotModelError(f"{source}: the body group must hold every fixed-base link "
                                  "(groups must be contiguous after ordering)")
        return slice(sel[0], sel[-1] + 1)

    arm = _slice([i for i, ln in enumerate(links) if ln in arm_links])
    body = _slice([i for i, ln in enumerate(links) if ln in body_links])
    return SphereTables(
        links=tuple(links), anchor=torch.tensor(anchors, device=device, dtype=torch.long),
        local=torch.tensor(np.asarray(locals_), device=device, dtype=dtype), weights=w.to(device), radii=radii,
        pair_radii=radii[arm][:, None] + radii[body][None, :], arm=arm, body=body,
        moving=_slice([i for i, a in enumerate(anchors) if a != 0]),
        arm_carried=_slice([i for i, a in enumerate(anchors) if a >= 2]),
        torso_carried=_slice([i for i, a in enumerate(anchors) if a == 1]))
