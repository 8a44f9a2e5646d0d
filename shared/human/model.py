"""Human kinematic model of the paper's 12 posture features and its body volumes.

The kinematic tree is written from the joint figures of the paper's Move3D "HERAKLES" model
(``p3d_set_pos_axe x y z ax ay az``: each joint's position and axis in the zero pose, metres, body
frame at the pelvis; x forward, y left, z up). The 12 features (``shared.library.FEATURE_NAMES``)
drive these joints, in this order:

=====  ==========================  ========================================================
index  feature                     joint
=====  ==========================  ========================================================
0-3    pelvis x, y, z, yaw         J1 free flyer: ``Trans(x, y, z) @ Rz(yaw)``
4-6    torso X, Y, Z               J2, J3, J4 at (0.037432, 0, 0.139749), axes x, y, z
7-9    right shoulder X, Z, Y      J8, J9, J10 at (-0.0112, -0.23982, 0.428571), axes x, z, -y
10     right arm translation       J11 prismatic along the upper arm (zero pose -y), lengthens it
11     right elbow Z               J12 at (-0.007033, -0.446428, 0.430224), axis z
=====  ==========================  ========================================================

Joints compose as a product of exponentials over the zero-pose axes (which is what a chain of
``p3d_set_pos_axe`` joints is): a point fixed to link ``L`` at zero-pose position ``p`` is at
``R_L @ p + t_L``. Angles are right-handed about the listed axes. The conventions were checked on
the paper's motion library (see docs/human-model.md and ``tests/shared/test_human.py``).

Body volumes are capsules of human size (the macro has no geometry). The left arm hangs rigidly
at the side of the torso; the head moves with the torso; the legs are not modelled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "N_FEATURES",
    "HumanError",
    "Segment",
    "HumanModel",
    "check_features",
]

N_FEATURES = 12

# Zero-pose joint positions of the HERAKLES macro (body frame at the pelvis, metres).
P_TORSO = np.array([0.037432, 0.0, 0.139749])      # J2-J4
P_NECK = np.array([0.023497, 0.0, 0.593966])       # J5-J7 (head joints, not driven by the features)
P_R_SHOULDER = np.array([-0.0112, -0.23982, 0.428571])   # J8-J10
P_R_ELBOW = np.array([-0.007033, -0.446428, 0.430224])   # J12
P_R_WRIST = np.array([-0.004259, -0.697, 0.43478])       # J14-J16
P_R_HAND = np.array([-0.004259, -0.85, 0.43478])         # J40 rPalm, 0.15 m beyond the wrist
P_L_SHOULDER = np.array([-0.0112, 0.23982, 0.428571])    # J17-J19
ARM_AXIS = np.array([0.0, -1.0, 0.0])                    # J11 translation: along the zero-pose upper arm

# Left arm, rigid, hanging at the side (torso link); lengths of the stretched right arm's typical size.
P_L_ELBOW = np.array([-0.02, 0.25, 0.13])
P_L_WRIST = np.array([0.0, 0.25, -0.12])
P_L_HAND = np.array([0.01, 0.25, -0.27])
P_HEAD = np.array([0.03, 0.0, 0.70])

# Links (rigid bodies) of the tree.
PELVIS, TORSO, R_UPPER, R_UPPER_END, R_FORE = range(5)
LINK_NAMES = ("pelvis", "torso", "r_upper_arm", "r_upper_arm_end", "r_forearm")

# Largest arm translation the surface sampling plans for (the data reach about 0.22 m; the macro allows 0.5).
MAX_ARM_TRANSLATION = 0.30


class HumanError(ValueError):
    """Bad input to the human model (wrong shape, non-finite value); the message says which."""


@dataclass(frozen=True)
class Segment:
    """One capsule: the segment between two link-fixed points, swept by a sphere of ``radius``.

    ``p0`` is fixed to link ``link0`` and ``p1`` to ``link1`` (zero-pose coordinates). Both links
    have the same orientation (they differ at most by the prismatic arm translation), so the
    capsule's surface is rigid apart from its length.
    """

    name: str
    link0: int
    p0: tuple[float, float, float]
    link1: int
    p1: tuple[float, float, float]
    radius: float


SEGMENTS: tuple[Segment, ...] = (
    Segment("pelvis", PELVIS, (0.02, -0.09, 0.0), PELVIS, (0.02, 0.09, 0.0), 0.11),
    Segment("torso", TORSO, (0.03, 0.0, 0.12), TORSO, (0.01, 0.0, 0.40), 0.13),
    Segment("shoulders", TORSO, (-0.011, -0.17, 0.41), TORSO, (-0.011, 0.17, 0.41), 0.07),
    Segment("head", TORSO, (0.03, 0.0, 0.66), TORSO, (0.03, 0.0, 0.74), 0.10),
    Segment("r_upper_arm", R_UPPER, tuple(P_R_SHOULDER), R_UPPER_END, tuple(P_R_ELBOW), 0.05),
    Segment("r_forearm", R_FORE, tuple(P_R_ELBOW), R_FORE, tuple(P_R_WRIST), 0.04),
    Segment("r_hand", R_FORE, tuple(P_R_WRIST), R_FORE, tuple(P_R_HAND), 0.045),
    Segment("l_upper_arm", TORSO, tuple(P_L_SHOULDER), TORSO, tuple(P_L_ELBOW), 0.05),
    Segment("l_forearm", TORSO, tuple(P_L_ELBOW), TORSO, tuple(P_L_WRIST), 0.04),
    Segment("l_hand", TORSO, tuple(P_L_WRIST), TORSO, tuple(P_L_HAND), 0.045),
)

_L0 = [s.link0 for s in SEGMENTS]
_L1 = [s.link1 for s in SEGMENTS]
_P0 = np.array([s.p0 for s in SEGMENTS])
_P1 = np.array([s.p1 for s in SEGMENTS])

# name -> (link, zero-pose position)
JOINTS: tuple[tuple[str, int, np.ndarray], ...] = (
    ("pelvis", PELVIS, np.zeros(3)),
    ("torso", TORSO, P_TORSO),
    ("neck", TORSO, P_NECK),
    ("head", TORSO, P_HEAD),
    ("r_shoulder", R_UPPER, P_R_SHOULDER),
    ("r_elbow", R_UPPER_END, P_R_ELBOW),
    ("r_wrist", R_FORE, P_R_WRIST),
    ("r_hand", R_FORE, P_R_HAND),
    ("l_shoulder", TORSO, P_L_SHOULDER),
    ("l_elbow", TORSO, P_L_ELBOW),
    ("l_wrist", TORSO, P_L_WRIST),
    ("l_hand", TORSO, P_L_HAND),
)


def check_features(features: np.ndarray, what: str = "features") -> np.ndarray:
    """``features`` as a float64 ``(..., 12)`` array of finite values.

    Raises:
        HumanError: If the last axis is not 12 long or a value is NaN or infinite (the message names ``what``).
    """
    f = np.asarray(features, dtype=np.float64)
    if f.ndim < 1 or f.shape[-1] != N_FEATURES:
        raise HumanError(f"{what}: expected shape (..., {N_FEATURES}), got {f.shape}")
    if not np.all(np.isfinite(f)):
        raise HumanError(f"{what}: contains NaN or infinite values")
    return f


def _rot(axis: str, angle: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` right-handed rotations by ``angle (...)`` about a coordinate axis."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(angle), np.zeros_like(angle)
    if axis == "x":
        rows = ((o, z, z), (z, c, -s), (z, s, c))
    elif axis == "y":
        rows = ((c, z, s), (z, o, z), (-s, z, c))
    else:
        rows = ((c, -s, z), (s, c, z), (z, z, o))
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def _about(r_parent: np.ndarray, t_parent: np.ndarray, r_joint: np.ndarray, point: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """Compose a parent link with a rotation ``r_joint`` about the zero-pose ``point``."""
    r = r_parent @ r_joint
    t = t_parent + np.einsum("...ij,...j->...i", r_parent, point - np.einsum("...ij,j->...i", r_joint, point))
    return r, t


def _ring_offsets(radius: float, spacing: float, u: np.ndarray, w: np.ndarray, phase: float) -> np.ndarray:
    n = max(6, math.ceil(2 * math.pi * radius / spacing))
    a = phase * math.pi / n + 2 * math.pi * np.arange(n) / n
    return radius * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * w)


def _capsule_template(seg: Segment, spacing: float, interior: bool) -> tuple[np.ndarray, np.ndarray]:
    """Surface samples of one capsule: ``(s (P,), offset (P, 3))``, point = p0 + s (p1 - p0) + R offset.

    ``s`` in [0, 1] places a sample along the axis (its endpoints for the caps); ``offset`` is in
    zero-pose coordinates. The axial step is planned for the longest stretch of the segment.
    """
    p0, p1 = np.asarray(seg.p0), np.asarray(seg.p1)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    axis = axis / length
    if seg.link0 != seg.link1:  # the prismatic joint stretches this segment
        length += MAX_ARM_TRANSLATION
    u = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    radii = [seg.radius]
    if interior:
        k = 1
        while seg.radius - k * spacing > 0.5 * spacing:
            radii.append(seg.radius - k * spacing)
            k += 1
    s_all, off_all = [], []
    for r in radii:
        # cylinder rings
        n_rings = max(1, math.ceil(length / spacing)) + 1
        for i, s in enumerate(np.linspace(0.0, 1.0, n_rings)):
            off = _ring_offsets(r, spacing, u, w, phase=i % 2)
            s_all.append(np.full(len(off), s))
            off_all.append(off)
        # hemispherical caps (latitudes above the equator ring)
        n_lat = max(1, math.ceil(0.5 * math.pi * r / spacing))
        for j in range(1, n_lat + 1):
            phi = 0.5 * math.pi * j / n_lat
            rr, h = r * math.cos(phi), r * math.sin(phi)
            ring = _ring_offsets(rr, spacing, u, w, phase=j % 2) if rr > 1e-9 else np.zeros((1, 3))
            if rr > 1e-9 and 2 * math.pi * rr < spacing:
                ring = ring[:1]
            for s, sign in ((0.0, -1.0), (1.0, 1.0)):
                s_all.append(np.full(len(ring), s))
                off_all.append(ring + sign * h * axis)
    if interior:  # the axis itself
        n_ax = max(1, math.ceil(length / spacing)) + 1
        s_all.append(np.linspace(0.0, 1.0, n_ax))
        off_all.append(np.zeros((n_ax, 3)))
    return np.concatenate(s_all), np.concatenate(off_all)


class HumanModel:
    """Forward kinematics and body volumes of the 12-feature human (batched numpy).

    All methods take ``features (..., 12)`` in any frame (the recorder's or, after
    :func:`shared.human.placement.place_in_scene`, the scene's) and return positions in that same frame.
    """

    JOINT_NAMES: tuple[str, ...] = tuple(name for name, _, _ in JOINTS)
    SEGMENT_NAMES: tuple[str, ...] = tuple(s.name for s in SEGMENTS)

    def __init__(self) -> None:
        self.segments = SEGMENTS
        self.radii = np.array([s.radius for s in SEGMENTS])
        self._templates: dict[tuple[float, bool], list[tuple[np.ndarray, np.ndarray]]] = {}

    # ---- kinematics -------------------------------------------------------------------------
    def link_transforms(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World poses of the links.

        Args:
            features: ``(..., 12)`` postures.

        Returns:
            ``(R (..., L, 3, 3), t (..., L, 3))`` with ``L = 5`` links (``LINK_NAMES``): a point at
            zero-pose position ``p`` on link ``l`` is at ``R[..., l] @ p + t[..., l]``.
        """
        f = check_features(features)
        r0 = _rot("z", f[..., 3])
        t0 = f[..., 0:3]
        r_torso = _rot("x", f[..., 4]) @ _rot("y", f[..., 5]) @ _rot("z", f[..., 6])
        r1, t1 = _about(r0, t0, r_torso, P_TORSO)
        r_sh = _rot("x", f[..., 7]) @ _rot("z", f[..., 8]) @ _rot("y", -f[..., 9])
        r2, t2 = _about(r1, t1, r_sh, P_R_SHOULDER)
        t3 = t2 + np.einsum("...ij,j->...i", r2, ARM_AXIS) * f[..., 10:11]
        r4, t4 = _about(r2, t3, _rot("z", f[..., 11]), P_R_ELBOW)
        rs = np.stack([r0, r1, r2, r2, r4], axis=-3)
        ts = np.stack([t0, t1, t2, t3, t4], axis=-2)
        return rs, ts

    def joint_positions(self, features: np.ndarray) -> np.ndarray:
        """Positions of the named joints (``JOINT_NAMES``).

        Args:
            features: ``(..., 12)`` postures.

        Returns:
            ``(..., J, 3)`` positions, in the frame of the features' pelvis pose.
        """
        rs, ts = self.link_transforms(features)
        links = [link for _, link, _ in JOINTS]
        pts = np.stack([p for _, _, p in JOINTS])
        return np.einsum("...jab,jb->...ja", rs[..., links, :, :], pts) + ts[..., links, :]

    def hand_position(self, features: np.ndarray) -> np.ndarray:
        """``(..., 12) -> (..., 3)`` position of the right hand (palm point, 0.15 m past the wrist)."""
        rs, ts = self.link_transforms(features)
        return np.einsum("...ab,b->...a", rs[..., R_FORE, :, :], P_R_HAND) + ts[..., R_FORE, :]

    def capsules(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Body capsules (``SEGMENT_NAMES``).

        Args:
            features: ``(..., 12)`` postures.

        Returns:
            ``(ends (..., S, 2, 3), radii (S,))``: the segment endpoints and the capsule radii.
        """
        rs, ts = self.link_transforms(features)
        return self._ends(rs, ts), self.radii.copy()

    @staticmethod
    def _ends(rs: np.ndarray, ts: np.ndarray) -> np.ndarray:
        """``(..., L, 3, 3), (..., L, 3)`` link poses -> ``(..., S, 2, 3)`` capsule endpoints."""
        e0 = np.einsum("...sab,sb->...sa", rs[..., _L0, :, :], _P0) + ts[..., _L0, :]
        e1 = np.einsum("...sab,sb->...sa", rs[..., _L1, :, :], _P1) + ts[..., _L1, :]
        return np.stack([e0, e1], axis=-2)

    # ---- surface sampling -------------------------------------------------------------------
    def _template(self, spacing: float, interior: bool) -> list[tuple[np.ndarray, np.ndarray]]:
        key = (round(float(spacing), 9), bool(interior))
        if key not in self._templates:
            self._templates[key] = [_capsule_template(s, spacing, interior) for s in SEGMENTS]
        return self._templates[key]

    def n_surface_points(self, spacing: float = 0.02, interior: bool = False) -> int:
        """Number of points :meth:`surface_points` returns per posture."""
        return sum(len(s) for s, _ in self._template(spacing, interior))

    def surface_points(self, features: np.ndarray, spacing: float = 0.02, interior: bool = False) -> np.ndarray:
        """Points on the body's capsule surfaces, at most ``spacing`` apart.

        The sample pattern is computed once per spacing in each segment's zero-pose frame and then
        moved rigidly (the upper arm is also stretched by the arm translation).

        Args:
            features: ``(..., 12)`` postures.
            spacing: Largest distance (m) between neighbouring samples (default 2 cm).
            interior: Also sample concentric inner shells and the axis (a solid body rather than
                its surface), for coarse voxel grids.

        Returns:
            ``(..., P, 3)`` points; P is the same for every posture (:meth:`n_surface_points`).
        """
        if not (isinstance(spacing, int | float) and math.isfinite(spacing) and spacing > 0):
            raise HumanError(f"spacing must be a positive number of metres, got {spacing!r}")
        rs, ts = self.link_transforms(features)
        ends = self._ends(rs, ts)
        out = []
        for k, (seg, (s, off)) in enumerate(zip(SEGMENTS, self._template(spacing, interior), strict=True)):
            e0, e1 = ends[..., k, 0, :], ends[..., k, 1, :]
            rot = rs[..., seg.link0, :, :]
            pts = (e0[..., None, :] + s[:, None] * (e1 - e0)[..., None, :]
                   + off @ np.swapaxes(rot, -1, -2))
            out.append(pts)
        return np.concatenate(out, axis=-2)
