"""How an experiment is run: the product's protocol, or the paper's as its authors' code ran it.

``product`` (the default) is the product's own: the robot follows its plan in time at ``robot_speed`` of
the PR2's velocity limits, 0.5 s per step; the planner integrates its costs over time, charges its goal's
dwell and picks the least total cost; Table I integrates the penetration over time.

``paper`` is the protocol of the authors' code, jmainpri/libmove3d-planners at aa1e6bf ("Paper
submission", 2013-03-26), read where the paper is silent (docs/experiments.md lists each value, its file
and line, and what the product does differently):

* pace: the human advances 5 of 100 frames per step for 20 steps (the product does too); the robot
  executes a fixed configuration-space length of its best path per step, 10 x 0.005 = 0.05 in the side scene
  and 17 x 0.005 = 0.085 in the facing scene (``HRICS_HumanPredictionSimulator.cpp`` constructor and
  ``execute()``), measured as Move3D measures it (a joint-space Euclidean norm weighing a revolute joint by
  the size of its body, ``p3d_dist_config``); after step 20 the rest of the path, without replanning;
* STOMP: 10 rollouts of which the previous iteration's best 5 are reused, 51 iterations (the loop breaks
  after iteration 50), the remaining path re-cut into 100 segments, noise 0.002 x N(0, R^-1) the same for
  every joint (``policy_improvement*.cpp``, ``params_pipeline_parallel_*``);
* costs summed per waypoint (no time weighting, no goal dwell); the goal of the least prediction cost
  wins each step, no hysteresis (``getBestPathId()``);
* prediction: each class's swept volume of its regressed (GMR) motion (``foresight train --volume
  paper``), p(c) a softmax of each class's mean per-frame log-likelihood (``HRICS_ClassifyMotion.cpp``);
* Table I: the executed path's penetration integrated along its configuration-space length, sampled every
  0.005, against the final prediction (``Trajectory::cost()`` after ``run()``);
* trials: on the paper's library the authors' human motions, 25-29 (side scene) and 77 (facing scene), the
  library indexed as 25 x class + demonstration: compound_1 #0-4 and compound_3 #2; the paper's library is
  recognised by those demonstrations' values (:data:`AUTHORS_DIGESTS`), not by its class names, which every
  CSV library has;
* scenes: Table I in the authors' side-by-side scene, ``PR2TwoCupsSideParallel`` (the one
  ``launch_pipeline_parallel_side_by_side`` loads; the robot beside the human), Fig. 9 in
  ``PR2TwoCupsFacing`` (its ``Parallel`` variant holds the same poses).
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from shared.runtime import UserError

if TYPE_CHECKING:
    from shared.library import MotionLibrary

log = logging.getLogger(__name__)

__all__ = ["PROTOCOLS", "Protocol", "PAPER", "PRODUCT", "protocol", "move3d_path_weights", "AUTHORS_TRIALS", "TRIALS",
           "authors_trial", "trial_digest", "AUTHORS_DIGESTS", "run_pacing", "settings_run"]

PROTOCOLS = ("product", "paper")

TABLE1_SCENE = "pr2_two_cups_side"
"""The product protocol's Table I scene."""
SWITCH_SCENE = "pr2_two_cups_facing"
"""The goal switch's scene (Fig. 8-9)."""
DEFAULT_PACES = {"product": (0.05, 0.1, 0.25, 0.5, 1.0),
                 "paper": (0.0125, 0.025, 0.05, 0.1, 0.2)}
"""Paces of ``foresight eval pace`` per protocol: fractions of the velocity limits (product), path length per step
(paper)."""

AUTHORS_TRIALS = {"pr2_two_cups_side_parallel": ("compound_1", (0, 1, 2, 3, 4)),
                  "pr2_two_cups_side": ("compound_1", (0, 1, 2, 3, 4)), "pr2_two_cups_facing": ("compound_3", (2,))}
"""The authors' human motions per scene, as (class, demonstrations) of the paper's library: ids 25-29 and 77
(move3d-launch ``human_traj_id``; comments of ``HRICS_initOccupancyPredictionFramework``), id = 25 x class + demo."""

AUTHORS_DIGESTS = {("compound_1", (0, 1, 2, 3, 4)): "47c6606b93489145", ("compound_3", (2,)): "fa434d7949fb6406"}
""":func:`trial_digest` of each authors' trial in the paper's library (its CSVs, or an .npz converted from them)."""

_R_INV_MAX_99 = 5315.97
"""Largest entry of R^-1 for the authors' 99 free waypoints (their 5-point acceleration stencil, no dt scaling)."""


@dataclass(frozen=True)
class Protocol:
    """What distinguishes a protocol (:data:`PRODUCT`, :data:`PAPER`).

    Attributes:
        name: ``product`` or ``paper``.
        path_per_step: Configuration-space length the robot executes per step, by scene (empty: in time).
        finish_path: Execute the rest of the best path after the last step.
        rollouts, reuse, waypoints, iterations, noise_std, uniform_noise: STOMP (None: the planner's default).
        integrate_costs, goal_dwell_s, goal_choice: The planner's cost composition and goal choice.
        free_paths: A goal whose path collides is invalid while another's is free (``PlannerConfig.free_paths``;
            the authors' goal choice has no such check: off in theirs).
        volume: The held-out models' occupancy volume (None: the trainer's default).
        evidence, temperature: The predictor's posterior (``PredictorConfig``).
        measure: Table I's integral: ``time`` (seconds) or ``path`` (configuration-space length, every 0.005).
        authors_trials: On the paper's library, run the authors' human motions (:data:`AUTHORS_TRIALS`).
        table1_scene: Table I's scene.
    """

    name: str
    path_per_step: tuple[tuple[str, float], ...] = ()
    finish_path: bool = False
    rollouts: int | None = None
    reuse: int | None = None
    waypoints: int | None = None
    iterations: int | None = None
    noise_std: float | None = None
    uniform_noise: bool = False
    integrate_costs: bool = True
    goal_dwell_s: float | None = None
    goal_choice: str = "total"
    free_paths: bool = True
    volume: str | None = None
    evidence: str = "sum"
    temperature: float = 0.0
    measure: str = "time"
    authors_trials: bool = False
    table1_scene: str = "pr2_two_cups_side"

    def pace(self, scene: str) -> float:
        """The path length per step in ``scene`` (0: the robot follows its plan in time)."""
        return dict(self.path_per_step).get(scene, 0.0)

    def stomp_iterations(self, asked: int | None) -> int:
        """STOMP's iterations per step: ``asked`` (``Timing.iterations``), else this protocol's, else the planner's."""
        from services.planner.config import StompConfig

        return asked or self.iterations or StompConfig.iterations


PRODUCT = Protocol("product")

PAPER = Protocol(
    "paper",
    path_per_step=(("pr2_two_cups_side_parallel", 10 * 0.005), ("pr2_two_cups_side", 10 * 0.005),
                   ("pr2_two_cups_facing", 17 * 0.005)),
    finish_path=True, rollouts=10, reuse=5, waypoints=101, iterations=51,
    noise_std=0.002 * math.sqrt(_R_INV_MAX_99), uniform_noise=True,  # 0.002 x N(0, R^-1): 0.146 at the middle
    integrate_costs=False, goal_dwell_s=0.0, goal_choice="human", free_paths=False, volume="paper", evidence="mean",
    temperature=1.0, measure="path", authors_trials=True, table1_scene="pr2_two_cups_side_parallel")


def protocol(name: str) -> Protocol:
    """The protocol called ``name``.

    Raises:
        ValueError: For a name not in :data:`PROTOCOLS`.
    """
    if name not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {name!r}")
    return PAPER if name == "paper" else PRODUCT


TRIALS = ("auto", "authors", "cup")


def trial_digest(library: MotionLibrary, trial: tuple[str, tuple[int, ...]]) -> str:
    """A digest of the values of ``trial``'s demonstrations in ``library`` ("" where it lacks one of them).

    Rounded to 1e-9, the float64 values hash the same from the CSVs, from an .npz converted from them and from
    CSVs written back (``%.17g``).
    """
    names = list(library.class_names)
    pool = library.by_class(names.index(trial[0])) if trial[0] in names else []
    if not trial[1] or max(trial[1]) >= len(pool):
        return ""
    h = hashlib.sha256()
    for i in trial[1]:
        h.update(np.round(np.asarray(pool[i].features, dtype=np.float64), 9).astype("<f8").tobytes())
    return h.hexdigest()[:16]


def _not_theirs(library: MotionLibrary, trial: tuple[str, tuple[int, ...]]) -> str:
    """Why ``library`` is not the paper's, where the authors' ``trial`` was run ("": it is)."""
    digest = trial_digest(library, trial)
    if not digest:
        return f"its {trial[0]} has fewer than {max(trial[1]) + 1} demonstrations"
    if digest != AUTHORS_DIGESTS[trial]:
        return (f"its {trial[0]} demonstrations {', '.join(map(str, trial[1]))} are not the paper's (digest {digest}, "
                f"the paper's {AUTHORS_DIGESTS[trial]})")
    return ""


def authors_trial(trials: str, prot: Protocol, scene: str, library: MotionLibrary
                  ) -> tuple[str, tuple[int, ...]] | None:
    """The authors' (class, demonstrations) to run, or None for the product's choice (the class at the human's cup).

    Args:
        trials: ``authors``, ``cup`` or ``auto`` (the authors' with a protocol that says so, on the paper's library).
        prot: The protocol.
        scene: The scene's name (the authors ran one motion set per scene).
        library: The library. The paper's is recognised by its values (:data:`AUTHORS_DIGESTS`): any CSV library
            has a class ``compound_1``.

    Raises:
        ValueError: An unknown ``trials``.
        UserError: ``authors`` where the scene has no authors' trial or the library is not the paper's.
    """
    if trials not in TRIALS:
        raise ValueError(f"trials must be one of {', '.join(TRIALS)}, got {trials!r}")
    trial = AUTHORS_TRIALS.get(scene)
    usable = trial is not None and trial[0] in library.class_names
    if trials == "authors" and trial is None:
        raise UserError(f"--trials authors: the authors ran no trial in scene {scene} (they ran "
                        f"{', '.join(f'{k}: {v[0]}' for k, v in AUTHORS_TRIALS.items())})")
    if trials == "authors" and not usable:  # the scene is theirs, the library is not: it said "in this scene"
        raise UserError(f"--trials authors: this library has no class {trial[0]!r}, the one the authors ran in "
                        f"scene {scene} (their motions are of the paper's library, "
                        "../shared/data/paper-library)")
    why = _not_theirs(library, trial) if usable else ""
    if trials == "authors" and why:  # its compound_1 is not the motions the authors' costs are of
        raise UserError(f"--trials authors: this library is not the paper's: {why} (the authors' motions are of "
                        "../shared/data/paper-library)")
    if trials == "auto" and prot.authors_trials and usable and why:
        log.warning("%s", f"{prot.name} protocol: the authors' trials and the comparison with their runs are skipped: "
                          f"this library is not the paper's: {why}")
        return None
    if trials == "authors" or (trials == "auto" and prot.authors_trials and usable):
        return trial
    return None


def run_pacing(prot: Protocol, scene: str, weights: np.ndarray | None) -> dict[str, Any]:
    """The :class:`~services.experiments.harness.RunSpec` fields a protocol sets in ``scene``: pace and posterior.

    Raises:
        UserError: The protocol paces the robot along its path but knows no pace for ``scene``.
    """
    pace = prot.pace(scene)
    if prot.path_per_step and not pace:
        raise UserError(f"--protocol {prot.name}: the authors' pace is known for the scenes "
                        f"{', '.join(dict(prot.path_per_step))}, not for {scene}")
    return {"path_per_step": pace, "path_weights": tuple(weights) if pace and weights is not None else (),
            "finish_path": prot.finish_path, "evidence": prot.evidence, "temperature": prot.temperature}


def move3d_path_weights(robot: object) -> np.ndarray:
    """Move3D's per-joint weights of configuration-space length, from the robot's collision spheres.

    Move3D (``p3d_jnt_calc_dof_dist``) weighs a revolute joint's angle by the largest distance from the joint
    to a vertex of the body it moves (a joint without a body takes the next body's down the chain) and a
    prismatic joint by 1. The product has no meshes: a body's vertices are its collision spheres' far sides
    (``|centre - joint| + radius``) in the robot's start configuration.

    Args:
        robot: A :class:`~shared.robot.PR2` (``fk_links``, ``sphere_centers``, ``sphere_anchor``, ``q_start``).

    Returns:
        ``(D,)`` weights (m per rad; 1 for the torso lift).
    """
    import torch  # here: the protocols load without torch (foresight eval --help)

    q = robot.q_start if getattr(robot, "q_start", None) is not None else (robot.lower + robot.upper) / 2
    q = torch.as_tensor(q, dtype=robot.dtype, device=robot.device)
    frames = robot.fk_links(q).double().cpu().numpy()  # (L, 4, 4): root, each joint's child, tool
    centres = robot.sphere_centers(q).double().cpu().numpy()  # (S, 3)
    radii = robot.sphere_radii.double().cpu().numpy()
    anchor = robot.sphere_anchor.cpu().numpy()
    d = robot.dof
    reach = np.zeros(d)
    for j in range(d):  # joint j moves link j + 1; its origin is that link's frame origin
        mine = anchor == j + 1
        if mine.any():
            reach[j] = float(np.max(np.linalg.norm(centres[mine] - frames[j + 1, :3, 3], axis=-1) + radii[mine]))
    for j in range(d - 2, -1, -1):  # a joint without a body: the next body's down the chain
        if reach[j] == 0.0:
            reach[j] = reach[j + 1]
    prismatic = np.array([n.endswith("torso_lift_joint") for n in robot.joint_names])
    return np.where(prismatic, 1.0, reach)


def settings_run(name: str, timing: Any, volume: str | None, scene: str, path_per_step: float | None = None
                 ) -> dict[str, Any]:
    """``timing`` (a :class:`~services.experiments.planners.Timing`) and ``volume`` as protocol ``name`` ran them.

    An option left unset (None) is the protocol's, else the planner's or the trainer's default: the paper
    protocol's JSON said ``"volume": null``, ``"iterations": null``, ``"rollouts": null`` and ``"reuse": null``
    where ``paper``, 51, 10 and 5 ran. The robot's pace is the one that ran: ``robot_speed`` where it follows its
    plan in time, else ``path_per_step`` in ``scene`` (``path_per_step`` given: a pace sweep's; the paper
    protocol's JSON said ``"robot_speed": 0.25``, which paces nothing there, and not the 0.05 it ran).
    """
    import dataclasses

    from services.planner.config import StompConfig
    from services.predictor.volumes import DEFAULT_VOLUME

    prot = protocol(name)
    times = dataclasses.asdict(timing)
    times["iterations"] = prot.stomp_iterations(times["iterations"])  # as build_planner sets them
    for key in ("rollouts", "reuse"):
        times[key] = next(v for v in (times[key], getattr(prot, key), getattr(StompConfig, key)) if v is not None)
    if pace := prot.pace(scene):
        del times["robot_speed"]
        times["path_per_step"] = pace if path_per_step is None else path_per_step
    return {"timing": times, "volume": volume or prot.volume or DEFAULT_VOLUME}
