"""Arm inverse kinematics of the PR2: world tool poses -> configurations, the torso lift held.

pytorch-kinematics' damped least-squares IK (``PseudoInverseIK``) on the torso -> tool chain
(:meth:`PR2.arm_chain`) with the model's finite joint limits, from several seeds per target in one batch.
:class:`~shared.robot.pr2.PR2` exposes these as ``ik_solutions``, ``ik_batch`` and ``ik``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pytorch_kinematics as pk
import torch

from .files import RobotModelError

if TYPE_CHECKING:
    from .pr2 import PR2

__all__ = ["ik_solutions", "ik_batch"]


def ik_solutions(robot: PR2, targets: np.ndarray | torch.Tensor, q_seed: Any, n_seeds: int = 24, seed: int = 0,
                 pos_tolerance: float = 2e-3, rot_tolerance: float = 2e-2, max_iterations: int = 80
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Arm IK for M world targets from N seeds each, the torso held at ``q_seed``'s lift.

    Seeds: ``q_seed``'s arm plus ``n_seeds - 1`` uniform samples within the limits (deterministic
    from ``seed``); the solver clamps to the limits every step.

    Args:
        robot: The PR2 (placed in the world).
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
    q0 = robot.validate_configuration(q_seed, what="IK seed")
    tw = torch.as_tensor(np.asarray(targets, dtype=np.float64) if not torch.is_tensor(targets)
                         else targets.detach().cpu().numpy(), dtype=torch.float64)
    if tw.ndim != 3 or tw.shape[1:] != (4, 4) or not torch.isfinite(tw).all():
        raise RobotModelError(f"IK targets must be finite (M, 4, 4), got {tuple(tw.shape)}")
    # world -> torso_lift_link frame at the seed's lift
    t_torso = robot.fk_links(q0.unsqueeze(0))[0, 1].double().cpu()  # world-from-torso_lift_link
    local = torch.linalg.inv(t_torso) @ tw
    ch = robot.arm_chain()
    gen = torch.Generator().manual_seed(seed)
    lo, hi = robot.lower[1:].cpu(), robot.upper[1:].cpu()
    rand = lo + (hi - lo) * torch.rand(max(n_seeds - 1, 0), robot.dof - 1, generator=gen, dtype=robot.dtype)
    seeds = torch.cat([q0[1:].cpu().unsqueeze(0), rand]).to(robot.device, robot.dtype)
    solver = pk.PseudoInverseIK(ch, pos_tolerance=pos_tolerance, rot_tolerance=rot_tolerance,
                                retry_configs=seeds, joint_limits=torch.stack([ch.low, ch.high], -1),
                                max_iterations=max_iterations, early_stopping_no_improvement=None,
                                lr=0.5, clamp_to_limits=True)
    sol = solver.solve(pk.Transform3d(matrix=local.to(robot.device, robot.dtype)))
    qa = sol.solutions  # (M, N, 7)
    full = torch.cat([q0[0].expand(*qa.shape[:2], 1), qa], dim=-1)
    inside = robot.within_limits(full)
    full = torch.minimum(torch.maximum(full, robot.lower), robot.upper)
    return full, sol.converged & inside, sol.err_pos, sol.err_rot


def ik_batch(robot: PR2, targets: np.ndarray | torch.Tensor, q_seed: Any, **kwargs: Any
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Like :func:`ik_solutions`, keeping per target the converged solution closest to ``q_seed``.

    Returns:
        ``(q, ok, pos_err, rot_err)``: ``(M, D)`` (within the limits), ``(M,)`` bool, ``(M,)``, ``(M,)``.
    """
    q, good, ep, er = ik_solutions(robot, targets, q_seed, **kwargs)
    q0 = robot.validate_configuration(q_seed, what="IK seed")
    dist = (q - q0).abs().sum(-1)
    score = torch.where(good, dist, dist + 1e6 + (ep + er) * 1e3)
    best = score.argmin(dim=1)
    ar = torch.arange(q.shape[0], device=q.device)
    return q[ar, best], good[ar, best], ep[ar, best], er[ar, best]
