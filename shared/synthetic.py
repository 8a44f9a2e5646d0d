"""Synthetic human-motion library: right-hand reaches to goals on a table, by IK on the human model.

The paper's recorded library cannot ship with the project; this generator is the embedded default.
Each class is a reach to one goal of a layout file (``shared/data/goals/table_8.toml``: goals in the
human's pelvis frame, two of them the cups of the default scene). Each demonstration is produced by
damped-least-squares IK on :class:`shared.human.HumanModel` (right arm, torso, a little pelvis)
tracking a hand path made of two overlapping minimum-jerk submovements (Flash & Hogan):

1. a *lift*: from the hanging rest posture forward and up to a via point a third of the way
   towards the goal (every class starts nearly the same way, as real reaches do);
2. a *transport* to the goal, starting early in the lift (4-15% of the reach).

The timing was tuned so that leave-one-out recognition (``foresight eval recognition``) follows the
paper's recorded library: near chance at 10-20% of the window, about half recognised at 40%, most
by 60% (docs/prediction.md has the tables).

Human-like variability, all drawn from one seeded generator: rest posture, arm length, first pelvis
pose in the recorder's frame, goal position, via point, onset, duration and overlap of the
submovements (so speed varies), the posture the IK prefers (elbow swivel), a slow pelvis sway and
Kinect-like jitter on every feature. Timing is expressed in fractions of the recording window, which
is sampled at ``n_samples`` (100) points like the paper's resampled data, in the same 12-feature
format. Optionally the hand returns to rest (as in the paper's recordings) instead of ending at the
goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from shared.data_files import finite_vector, read_toml
from shared.human import HumanModel
from shared.library import Demonstration, LibraryError, MotionLibrary

__all__ = ["SyntheticConfig", "GoalLayout", "load_layout", "generate_library", "DEFAULT_LAYOUT", "DEFAULT_CLASSES",
           "pelvis_frame"]

DEFAULT_LAYOUT = "table_8"
DEFAULT_CLASSES = 8
"""Classes of a generated library unless asked: the layout's first goals, by name."""
FEATURE_SETS = ("herakles", "wide16")

# Degrees of freedom the IK moves (feature indices): pelvis x, y, yaw, torso X, Y, Z, shoulder X, Z, Y, elbow.
IK_DOFS = np.array([0, 1, 3, 4, 5, 6, 7, 8, 9, 11])
# Stiffness of the pull towards the preferred posture, per dof (per m^2 or rad^2): it decides how the
# redundant body shares the reach (the arm does most of it, the torso leans for far goals, the pelvis
# barely moves). The residual hand error is about stiffness * displacement / lever arm (< 1 mm for the arm).
IK_POSTURE = np.array([0.5, 0.5, 0.05, 0.02, 0.006, 0.02, 2e-4, 2e-4, 1e-3, 2e-4])
# Levenberg step damping (does not change the solution, only how fast it is reached).
IK_DAMPING = 1e-3
# Joint limits of the features the IK moves (macro limits; the elbow does not hyperextend).
LIMITS = {
    4: (-math.radians(45), math.radians(45)),
    5: (-math.radians(20), math.radians(50)),
    6: (-math.radians(45), math.radians(45)),
    7: (-math.pi, math.pi),
    8: (-math.pi, math.pi),
    9: (-math.pi, math.pi),
    11: (0.0, 2.6),
}


@dataclass(frozen=True)
class SyntheticConfig:
    """Parameters of the synthetic demonstrations (times are fractions of the recording window).

    Attributes:
        n_samples: Samples per demonstration (the paper's: 100).
        onset: ``(low, high)`` uniform start of the movement.
        duration: ``(low, high)`` uniform duration of the reach.
        lift_fraction: ``(low, high)`` duration of the lift submovement, fraction of the reach.
        transport_start: ``(low, high)`` start of the transport submovement, fraction of the reach.
        lift: Mean lift of the hand (pelvis frame: forward, left, up), metres.
        lift_noise: Standard deviation of the lift per axis, metres.
        lift_goal_fraction: How much of the way to the goal the via point already is.
        goal_noise: Standard deviation of the reached position around the goal, metres.
        return_to_rest: Bring the hand back to rest after the reach (like the paper's recordings);
            then the reach takes the first part of the window and the return the rest.
        ik_iterations: DLS iterations per sample.
        posture_weight: Scale of the IK's pull towards the preferred posture (``IK_POSTURE``).
        jitter_angle: Standard deviation of the measurement jitter on angles, radians.
        jitter_position: Standard deviation of the measurement jitter on the pelvis position, metres.
        sway: Standard deviation of the slow pelvis sway, metres.
        recorder_pelvis: Mean first pelvis pose in the recorder's frame (x, y, z, yaw).
        recorder_noise: Its standard deviation per entry.
    """

    n_samples: int = 100
    onset: tuple[float, float] = (0.02, 0.12)
    duration: tuple[float, float] = (0.5, 0.7)
    lift_fraction: tuple[float, float] = (0.45, 0.6)
    transport_start: tuple[float, float] = (0.04, 0.15)
    lift: tuple[float, float, float] = (0.20, -0.03, 0.16)
    lift_noise: float = 0.035
    lift_goal_fraction: float = 0.35
    goal_noise: float = 0.025
    return_to_rest: bool = False
    ik_iterations: int = 3
    posture_weight: float = 1.0
    jitter_angle: float = 0.006
    jitter_position: float = 0.003
    sway: float = 0.01
    recorder_pelvis: tuple[float, float, float, float] = (1.8, 1.7, 0.975, -2.4)
    recorder_noise: tuple[float, float, float, float] = (0.05, 0.05, 0.01, 0.08)

    def validate(self) -> None:
        """Raise :class:`LibraryError` on a bad parameter."""
        if self.n_samples < 10:
            raise LibraryError(f"synthetic: n_samples must be >= 10, got {self.n_samples}")
        for name in ("onset", "duration", "lift_fraction", "transport_start"):
            lo, hi = getattr(self, name)
            if not 0.0 <= lo <= hi <= 1.0:
                raise LibraryError(f"synthetic: {name} must be 0 <= low <= high <= 1, got {(lo, hi)}")
        if self.onset[1] + self.duration[1] > 1.0:
            raise LibraryError("synthetic: onset + duration must fit in the window (<= 1)")
        if self.ik_iterations < 1:
            raise LibraryError(f"synthetic: ik_iterations must be >= 1, got {self.ik_iterations}")


@dataclass(frozen=True)
class GoalLayout:
    """Reach goals in the human's pelvis frame (at the first posture)."""

    name: str
    goal_names: list[str]
    goals: np.ndarray  # (M, 3)
    source: str


def pelvis_frame(scene) -> tuple[np.ndarray, np.ndarray]:
    """``(rotation (3, 3), origin (3,))`` of the scene's pelvis frame (the layouts' goals are in it)."""
    yaw = scene.human.pelvis_yaw
    rot = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return rot, np.asarray(scene.human.pelvis_xyz, dtype=np.float64)


def _vec(where: str, raw: Any, n: int) -> np.ndarray:
    return finite_vector(where, raw, n, LibraryError)


def load_layout(layout: str | Path | None = None, scene=None) -> GoalLayout:
    """Read a goal layout file (TOML; ``None`` or a bare name: an embedded one).

    Args:
        layout: Path of a ``.toml`` file, or the name of an embedded layout (default ``table_8``).
        scene: Scene that ``cup``/``surface`` entries refer to (default: the layout's ``scene``).

    Returns:
        The goals in the human's pelvis frame.

    Raises:
        LibraryError: If the file is missing or an entry is malformed.
    """
    from shared.scene import load_scene

    data, source = read_toml(layout, "goals", DEFAULT_LAYOUT, "goal layout", LibraryError)
    entries = data.get("goals")
    if not isinstance(entries, list) or not entries:
        raise LibraryError(f"goal layout {source!r}: no [[goals]] entries")
    if scene is None:
        scene = load_scene(data.get("scene"))
    rot, origin = pelvis_frame(scene)
    names, goals = [], []
    for i, g in enumerate(entries):
        where = f"goal layout {source!r}: goals[{i}]"
        name = str(g.get("name", f"goal_{i}"))
        keys = [k for k in ("cup", "xy", "position") if k in g]
        if len(keys) != 1:
            raise LibraryError(f"{where}: give exactly one of cup, xy (+ height) or position")
        if "cup" in g:
            goal = rot.T @ (scene.cup(str(g["cup"])).center - origin)
        elif "xy" in g:
            xy = _vec(f"{where}.xy", g["xy"], 2)
            height = g.get("height", 0.06)
            if isinstance(height, bool) or not isinstance(height, int | float):
                raise LibraryError(f"{where}.height: expected a number, got {height!r}")
            surface = str(g.get("surface", data.get("surface", "table_top")))
            box = next((b for b in scene.boxes if b.name == surface), None)
            if box is None:
                raise LibraryError(f"{where}: scene {scene.name} has no box named {surface!r}")
            goal = np.array([xy[0], xy[1], box.upper[2] + float(height) - origin[2]])
        else:
            goal = _vec(f"{where}.position", g["position"], 3)
        names.append(name)
        goals.append(goal)
    if len(set(names)) != len(names):
        raise LibraryError(f"goal layout {source!r}: goal names must be unique")
    return GoalLayout(str(data.get("name", Path(source).stem)), names, np.array(goals), source)


def _min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile 10 s^3 - 15 s^4 + 6 s^5 of ``s`` clipped to [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def _rz(yaw: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    o, z = np.ones_like(yaw), np.zeros_like(yaw)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, ...], width: int) -> np.ndarray:
    """Unit-variance noise along axis 1 smoothed with a Hann window of ``width`` samples."""
    w = np.hanning(width + 2)[1:-1]
    w /= np.sqrt(np.sum(w * w))
    raw = rng.normal(size=(shape[0], shape[1] + width - 1) + shape[2:])
    out = np.zeros(shape)
    for k in range(width):
        out += w[k] * raw[:, k:k + shape[1]]
    return out


class _IK:
    """Batched damped-least-squares IK of the right hand over :data:`IK_DOFS`."""

    def __init__(self, model: HumanModel, posture_weight: float) -> None:
        self.model = model
        self.stiffness = np.diag(IK_POSTURE * posture_weight)
        self.damping = IK_DAMPING * np.eye(len(IK_DOFS)) + self.stiffness
        self.lo = np.full(12, -np.inf)
        self.hi = np.full(12, np.inf)
        for j, (a, b) in LIMITS.items():
            self.lo[j], self.hi[j] = a, b

    def step(self, q: np.ndarray, target: np.ndarray, preferred: np.ndarray) -> np.ndarray:
        """One DLS step: ``q (B, 12)``, ``target (B, 3)``, ``preferred (B, 12)`` -> ``(B, 12)``."""
        eps = 1e-5
        d = len(IK_DOFS)
        probe = np.repeat(q[:, None, :], d + 1, axis=1)
        probe[:, np.arange(1, d + 1), IK_DOFS] += eps
        hand = self.model.hand_position(probe)                    # (B, d+1, 3)
        jac = np.swapaxes((hand[:, 1:] - hand[:, :1]) / eps, 1, 2)  # (B, 3, d)
        err = target - hand[:, 0]
        lhs = np.swapaxes(jac, 1, 2) @ jac + self.damping
        rhs = np.einsum("bij,bi->bj", jac, err) + (preferred - q)[:, IK_DOFS] @ self.stiffness
        dq = np.linalg.solve(lhs, rhs[..., None])[..., 0]
        out = q.copy()
        out[:, IK_DOFS] += dq
        return np.clip(out, self.lo, self.hi)


def generate_library(n_classes: int = DEFAULT_CLASSES, n_demos: int = 25, seed: int = 0,
                     layout: str | Path | GoalLayout | None = None, scene=None,
                     config: SyntheticConfig | None = None) -> MotionLibrary:
    """Generate a synthetic library of right-hand reaches to table goals.

    Args:
        n_classes: Number of classes M (the first M goals of the layout).
        n_demos: Demonstrations per class N.
        seed: Seed of every random draw (same seed, same library).
        layout: Goal layout (a :class:`GoalLayout`, a TOML path or an embedded name; default
            ``table_8``).
        scene: Scene the layout's cups and table refer to (default: the layout's scene).
        config: Generator parameters (default :class:`SyntheticConfig`).

    Returns:
        The library: ``n_classes * n_demos`` demonstrations of ``config.n_samples`` samples, recorder
        frame, class names = goal names.

    Raises:
        LibraryError: On bad arguments (e.g. more classes than goals).
    """
    cfg = config or SyntheticConfig()
    cfg.validate()
    lay = layout if isinstance(layout, GoalLayout) else load_layout(layout, scene)
    if not 1 <= n_classes <= len(lay.goals):
        raise LibraryError(f"synthetic: n_classes must be 1..{len(lay.goals)} (goals in {lay.source}), "
                           f"got {n_classes}")
    if n_demos < 1:
        raise LibraryError(f"synthetic: n_demos must be >= 1, got {n_demos}")
    rng = np.random.default_rng(seed)
    model = HumanModel()
    b = n_classes * n_demos
    labels = np.repeat(np.arange(n_classes), n_demos)
    t_count = cfg.n_samples

    # --- per-demonstration draws (in a fixed order: the seed alone decides everything) -------
    pelvis0 = np.asarray(cfg.recorder_pelvis) + rng.normal(size=(b, 4)) * np.asarray(cfg.recorder_noise)
    rest = np.zeros((b, 12))
    rest[:, :4] = pelvis0
    rest[:, 4] = rng.normal(0.085, 0.02, b)       # torso X (slight lean right, as recorded)
    rest[:, 5] = rng.normal(0.12, 0.03, b)        # torso Y (slight forward lean)
    rest[:, 6] = rng.normal(-0.01, 0.01, b)       # torso Z
    rest[:, 7] = rng.normal(1.60, 0.05, b)        # shoulder X: arm hanging down
    rest[:, 8] = rng.normal(0.13, 0.05, b)        # shoulder Z
    rest[:, 9] = rng.normal(0.0, 0.25, b)         # shoulder Y: humeral twist
    rest[:, 10] = rng.normal(0.09, 0.012, b)      # arm translation: upper-arm length of the subject
    rest[:, 11] = rng.normal(0.42, 0.10, b)       # elbow: slightly bent
    rest[:, 11] = np.clip(rest[:, 11], 0.05, None)
    goal_noise = rng.normal(size=(b, 3)) * cfg.goal_noise * np.array([1.0, 1.0, 0.3])
    lift_noise = rng.normal(size=(b, 3)) * cfg.lift_noise
    onset = rng.uniform(*cfg.onset, b)
    duration = rng.uniform(*cfg.duration, b)
    duration = np.minimum(duration, 0.98 - onset)
    lift_frac = rng.uniform(*cfg.lift_fraction, b)
    transport_start = rng.uniform(*cfg.transport_start, b)
    pref_noise = rng.normal(size=(b, 12)) * np.array([0, 0, 0, 0.05, 0.03, 0.05, 0.03, 0.1, 0.1, 0.3, 0, 0.15])
    sway = _smooth_noise(rng, (b, t_count, 3), 25) * np.array([cfg.sway, cfg.sway, 2 * cfg.sway / 10])
    jitter = _smooth_noise(rng, (b, t_count, 12), 5)

    # --- hand path in the recorder frame ----------------------------------------------------
    rot0 = _rz(pelvis0[:, 3])                                             # (B, 3, 3)
    origin0 = np.concatenate([pelvis0[:, :3]], axis=1)
    goal_local = lay.goals[labels] + goal_noise
    goal = origin0 + np.einsum("bij,bj->bi", rot0, goal_local)
    hand0 = model.hand_position(rest)
    hand0_local = np.einsum("bji,bj->bi", rot0, hand0 - origin0)
    via_local = hand0_local + np.asarray(cfg.lift) + lift_noise + cfg.lift_goal_fraction * (goal_local - hand0_local)
    via = origin0 + np.einsum("bij,bj->bi", rot0, via_local)

    t = np.linspace(0.0, 1.0, t_count)[None, :]                          # (1, T)
    if cfg.return_to_rest:
        reach_dur = 0.5 * duration
    else:
        reach_dur = duration
    on, dur = onset[:, None], reach_dur[:, None]
    s1 = _min_jerk((t - on) / (lift_frac[:, None] * dur))
    t2 = on + transport_start[:, None] * dur
    s2 = _min_jerk((t - t2) / (on + dur - t2))
    path = (hand0[:, None] + s1[..., None] * (via - hand0)[:, None] + s2[..., None] * (goal - via)[:, None])
    if cfg.return_to_rest:
        t3 = on + dur + 0.1 * duration[:, None]
        s3 = _min_jerk((t - t3) / (0.4 * duration[:, None]))
        path = path + s3[..., None] * (hand0 - goal)[:, None]
        s2 = s2 * (1.0 - s3)

    # --- IK tracking, all demonstrations at once ---------------------------------------------
    ik = _IK(model, cfg.posture_weight)
    preferred_end = rest + pref_noise
    feats = np.zeros((b, t_count, 12))
    q = rest.copy()
    for k in range(t_count):
        blend = s2[:, k:k + 1]
        preferred = (1.0 - blend) * rest + blend * preferred_end
        for _ in range(cfg.ik_iterations):
            q = ik.step(q, path[:, k], preferred)
        feats[:, k] = q

    # --- small pelvis sway and measurement jitter ---------------------------------------------
    ramp = _min_jerk((t - on) / dur)[..., None]                           # sway grows with the motion
    feats[:, :, 0:3] += sway * np.maximum(ramp, 0.3)
    feats[:, :, 0:3] -= feats[:, :1, 0:3] - pelvis0[:, None, :3]        # first pelvis pose exact
    scale = np.full(12, cfg.jitter_angle)
    scale[[0, 1, 2, 10]] = cfg.jitter_position
    feats += jitter * scale
    feats[:, 0, :4] = pelvis0

    demos = []
    for i in range(b):
        m = int(labels[i])
        f = np.ascontiguousarray(feats[i])
        f.setflags(write=False)
        demos.append(Demonstration(m, lay.goal_names[m], i - m * n_demos, f,
                                   f"synthetic:{lay.name} seed={seed} class {m} demo {i - m * n_demos}"))
    source = f"synthetic:{lay.name} classes={n_classes} demos={n_demos} seed={seed}"
    return MotionLibrary(list(lay.goal_names[:n_classes]), demos, [], source)
