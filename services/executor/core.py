"""The executor's pure simulation: a PR2 arm that follows the chosen trajectory of the latest plan.

No Zenoh here (see :mod:`services.executor.service` for the loop around it). The simulation is a kinematic one: each
step of ``h`` seconds the arm moves towards the plan's reference at the next instant, with its joint velocities
scaled down uniformly (so the direction in joint space is kept) until every joint is within its velocity limit, and
every commanded configuration clamped to the joint limits.

Timing follows the paper's Fig. 4: the robot executes the plan of replanning step n-1 during step n. The core keeps
its own clock ``t`` (seconds of simulated time); the service decides when a plan is adopted
(:meth:`ExecutorCore.adopt`) and at which time a message counts as received (:meth:`ExecutorCore.note_occupancy`).
Safety: :meth:`ExecutorCore.stale_reason` says why the robot must hold (zero velocity) -- no plan yet, the latest
plan or occupancy older than ``stale_limit_s``, or a service it depends on gone (:meth:`ExecutorCore.note_peer`) --
and the reference's own clock stops while the robot holds, so execution resumes where it stopped when fresh data
arrives. A ``guard`` (real time: the separation guard, :mod:`services.executor.separation`) may refuse a step by
saying why: the robot holds as well. :func:`reason_kind` tells a change of hold reason from the same reason with
another age (what the service logs once).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from shared.lockstep import FIRST_PLAN
from shared.protocol import HUMAN_SOURCES, Plan, RobotState

from .config import ExecutorConfig, ExecutorError
from .reference import Reference
from .splice import Takeover, take_over

__all__ = ["ExecutorConfig", "ArmLimits", "ExecutorError", "ExecutorCore", "reason_kind"]


def reason_kind(reason: str) -> str:
    """A hold reason without its numbers: ``"plan is 0.61 s old (limit 0.50 s)"`` -> ``"plan is # s old (limit # s)"``.

    Two reasons of one kind differ only in the ages they quote; a change of kind is what gets logged.
    """
    return re.sub(r"\d+(?:\.\d+)?", "#", reason)


@dataclass(frozen=True)
class ArmLimits:
    """Joint names and limits of the simulated arm.

    Attributes:
        joint_names: The D joint names, in the order of every ``q`` the core handles.
        lower: ``(D,)`` lower joint limits.
        upper: ``(D,)`` upper joint limits.
        velocity: ``(D,)`` positive joint velocity limits (per second).
        continuous: The joints without position limits (``lower``/``upper`` are then the planner's [-pi, pi]); a
            robot may report them unwrapped (2 pi + 0.1), which :meth:`wrap` brings into that range.
    """

    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    continuous: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        d = len(self.joint_names)
        for name in ("lower", "upper", "velocity"):
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.shape != (d,) or not np.all(np.isfinite(arr)):
                raise ExecutorError(f"ArmLimits.{name}: expected {d} finite values, got shape {arr.shape}")
            object.__setattr__(self, name, arr)
        if np.any(self.upper < self.lower):
            bad = [n for n, lo, hi in zip(self.joint_names, self.lower, self.upper, strict=True) if hi < lo]
            raise ExecutorError(f"ArmLimits: upper limit below lower limit for {bad}")
        if np.any(self.velocity <= 0):
            raise ExecutorError("ArmLimits.velocity: limits must be > 0")
        if unknown := [n for n in self.continuous if n not in self.joint_names]:
            raise ExecutorError(f"ArmLimits.continuous: {unknown} are not joints of {list(self.joint_names)}")

    @property
    def dof(self) -> int:
        """Number of joints D."""
        return len(self.joint_names)

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """Clamp configurations ``(..., D)`` into the joint limits."""
        return np.clip(q, self.lower, self.upper)

    @property
    def continuous_mask(self) -> np.ndarray:
        """``(D,)`` bool: which joints are continuous."""
        return np.array([n in self.continuous for n in self.joint_names], dtype=bool)

    def wrap(self, q: np.ndarray) -> np.ndarray:
        """Configurations ``(..., D)`` with each continuous joint's angle brought into [-pi, pi)."""
        out = np.array(q, dtype=np.float64)
        c = self.continuous_mask
        out[..., c] = (out[..., c] + np.pi) % (2 * np.pi) - np.pi
        return out

    def unwrap_from(self, start: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Waypoints ``(N, D)`` whose continuous joints turn the short way from ``start`` ``(D,)``.

        ``start`` is a robot's own (possibly unwrapped) reading; each continuous joint then goes on the short way
        from waypoint to waypoint, never back round through the wrap.
        """
        c = self.continuous_mask
        out = np.array(q, dtype=np.float64)
        if c.any():
            out[:, c] = np.unwrap(np.vstack([np.asarray(start, dtype=np.float64)[None, c], out[:, c]]), axis=0)[1:]
        return out

    @classmethod
    def from_robot(cls, robot: object) -> ArmLimits:
        """Take the limits from a robot model with ``joint_names``, ``lower``, ``upper``, ``velocity_limits``.

        ``lower`` etc. may be torch tensors or numpy arrays (shared.robot.PR2 holds tensors).
        """

        def arr(x: object) -> np.ndarray:
            x = x.detach().cpu().numpy() if hasattr(x, "detach") else x
            return np.asarray(x, dtype=np.float64)

        return cls(tuple(robot.joint_names), arr(robot.lower), arr(robot.upper),  # type: ignore[attr-defined]
                   arr(robot.velocity_limits), tuple(getattr(robot, "continuous", ())))  # type: ignore[attr-defined]


@dataclass
class _Freshness:
    plan: float | None = None       # time (core clock) of the latest plan
    occupancy: float | None = None  # time (core clock) of the latest occupancy
    occupancy_of: tuple[int, int] | None = None  # (demo_id, index) of the pose the latest occupancy predicts from
    demo_end: tuple[int, int] | None = None      # (demo_id, last index) of the demonstration that ended
    lost: str | None = None  # why the person is not seen: the tracker lost them, or went (until a demonstration starts)
    last_demo: int | None = None  # demo_id of the last demonstration marker


class ExecutorCore:
    """Simulates the arm following the chosen trajectory of the latest adopted plan.

    Args:
        limits: Joint names and limits; every plan must name the same joints in the same order.
        q0: ``(D,)`` start configuration (clamped into the limits).
        config: The executor's options (uses ``stale_limit_s``, ``require_occupancy``, ``goal_tolerance``,
            ``velocity_scale``).
        guard: ``(q (D,), q_next (D,)) -> str``: why a step from ``q`` to ``q_next`` must not be taken (``""``: it
            may), asked before each step that moves (real time: :class:`services.executor.separation.SeparationGuard`).

    Attributes:
        t: Simulated time, seconds.
        q: ``(D,)`` current configuration.
        qd: ``(D,)`` current joint velocity (of the last step).
        plan: The plan being executed, or None.
        goal: Index of the goal being executed (-1 before the first plan).
        holding: Whether the last step held the robot; ``reason`` says why.
        reached: Whether the configuration is within ``goal_tolerance`` of the executed goal.
    """

    def __init__(self, limits: ArmLimits, q0: np.ndarray, config: ExecutorConfig | None = None,
                 guard: Callable[[np.ndarray, np.ndarray], str] | None = None) -> None:
        self.limits = limits
        self.config = config or ExecutorConfig()
        q0 = np.asarray(q0, dtype=np.float64)
        if q0.shape != (limits.dof,) or not np.all(np.isfinite(q0)):
            raise ExecutorError(f"start configuration: expected {limits.dof} finite values, got shape {q0.shape}")
        self.t = 0.0
        self.q = limits.clamp(q0)
        self.qd = np.zeros(limits.dof)
        self.plan: Plan | None = None
        self.reference: Reference | None = None
        self.tau = 0.0  # progress along the reference (stops while holding): seconds, or length with path_per_step
        self.taken = ""  # how the last plan was taken over: "start" (lock-step), "joined", "spliced", "led in"
        weights = self.config.path_weights
        if weights and len(weights) != limits.dof:
            raise ExecutorError(f"path_weights: expected {limits.dof} values, got {len(weights)}")
        self._path_weights = np.asarray(weights, dtype=np.float64) if weights else None
        self.goal = -1
        self.holding = True
        self.reason = FIRST_PLAN
        self.reached = False
        self.fresh = _Freshness()
        self.plans_adopted = 0
        self.gone: frozenset[str] = frozenset()  # services of hold_without whose token was lost (replaced, never
        # mutated: the transport's thread writes it while the loop reads it)
        self.seen: frozenset[str] = frozenset()  # services whose token was seen (replaced the same way)
        self.guard = guard  # (q, q_next) -> why not to step there (the separation guard, real time), or None

    # -- inputs ------------------------------------------------------------------------------

    def check_plan(self, plan: Plan) -> None:
        """Raise ExecutorError if ``plan`` does not fit this arm (joint names/order; a chosen path of 2+ waypoints)."""
        if tuple(plan.joint_names) != self.limits.joint_names:
            raise ExecutorError(f"Plan.joint_names: {list(plan.joint_names)} do not match the executor's "
                                f"{list(self.limits.joint_names)}")
        shape = np.shape(plan.trajectories)
        if len(shape) != 3 or shape[1] < 2 or not 0 <= plan.chosen < shape[0]:
            raise ExecutorError(f"Plan.trajectories: shape {shape} with chosen {plan.chosen}: the executor needs the "
                                "chosen trajectory with at least 2 waypoints")

    def adopt(self, plan: Plan, stamp: float | None = None) -> None:
        """Start executing ``plan``'s chosen trajectory now (at ``self.t``).

        In real time the arm takes it over from the reference it follows (:func:`splice.take_over`: joins a late plan
        where nearest, goes on to an early one's start, else is led in at its pace); ``goal`` is the new plan's at once.

        Args:
            plan: A decoded (hence validated) plan.
            stamp: Time (core clock) the plan counts as received for the staleness check; default now.

        Raises:
            ExecutorError: If the plan's joints differ from the arm's.
        """
        self.check_plan(plan)
        waypoints = self.limits.clamp(plan.trajectories[plan.chosen].astype(np.float64))
        self.plan, new = plan, Reference(waypoints, plan.dt, self._path_weights)
        taken = (take_over(new, self.q, self.reference, self.tau, self.config, self.limits.velocity)
                 if self.config.mode == "realtime" else Takeover(new, 0.0, "start"))  # lock-step: w0 is q
        self.reference, self.tau, self.taken = taken.reference, taken.progress, taken.how
        self.goal = int(plan.chosen)
        self.fresh.plan = self.t if stamp is None else float(stamp)
        self.plans_adopted += 1
        self._update_reached()

    def note_demonstration(self, event: str, demo_id: int = -1, n_samples: int = 0) -> None:
        """Record a DemoMarker event (``"start"``, ``"end"`` or ``"lost"``) of demonstration ``demo_id``.

        After the end of the observed demonstration the human stands still: the prediction made from its
        last pose (index ``n_samples - 1``) stays valid and its age no longer holds the robot, once that
        prediction has arrived (:attr:`human_ended`). A start requires fresh predictions again. A demonstration the
        tracker lost, mid-reach or after its end (the person out of view, another body, moved away from where it
        showed them), leaves the person's whereabouts unknown: with ``require_occupancy`` the robot holds until a
        demonstration starts again, a reach or the tracker's person seen at rest.
        """
        self.fresh.demo_end = (int(demo_id), int(n_samples) - 1) if event == "end" else None
        self.fresh.last_demo = int(demo_id)
        if event == "lost":
            self.fresh.lost = (f"the tracker lost the person (demonstration {int(demo_id)}: out of the sensor's view, "
                               "another body, or moved away)")
        elif event == "start":
            self.fresh.lost = None

    def note_occupancy(self, stamp: float | None = None) -> None:
        """Record that an occupancy prediction was received at ``stamp`` (core clock; default now)."""
        stamp = self.t if stamp is None else float(stamp)
        if self.fresh.occupancy is None or stamp > self.fresh.occupancy:
            self.fresh.occupancy = stamp

    def note_occupancy_of(self, demo_id: int, index: int) -> None:
        """Record the pose (``demo_id``, sample ``index``) the newest occupancy prediction was made from."""
        self.fresh.occupancy_of = (int(demo_id), int(index))

    @property
    def human_ended(self) -> bool:
        """Whether the demonstration ended and the latest occupancy is the one of its last pose.

        An end marker alone does not do (the predictor may be dead or behind: its latest prediction
        then describes an earlier posture, and its age must hold the robot).
        """
        end = self.fresh.demo_end
        return end is not None and self.fresh.occupancy_of == end

    def note_peer(self, service: str, alive: bool) -> bool:
        """Record that ``service``'s liveliness token appeared (``alive``) or was lost.

        While a service of ``hold_without`` is gone the robot holds, whatever the age of its last output. A human's
        source that plays a recording (``recorded_sources``: the replayer) counts as gone only when it goes in the
        middle of a demonstration: after its end marker the human stands still and its stream may end. A live one
        (the tracker) going at any time means nobody watches the person: before, a tracker killed after a reach's
        end let the robot go on around that reach's last prediction for good.

        Returns:
            Whether it was a recording's stream ending after its end marker (no fault, nothing changed).
        """
        if alive:
            self.seen = self.seen | {service}
        if service not in self.config.hold_without:
            return False
        if service in self.config.recorded_sources and not alive and self.fresh.demo_end is not None:
            return True  # the recording's stream ended (its end marker came first): the human stands still
        if service in HUMAN_SOURCES and service not in self.config.recorded_sources and not alive \
                and self.fresh.last_demo is not None:
            # back (a lost link) or started anew (a crash, restarted), it must say the person again: its last
            # demonstration may describe someone gone meanwhile (the tracker says the person again to an executor
            # that appears)
            self.fresh.lost = f"the {service} was gone (its last demonstration, {self.fresh.last_demo}, may be stale)"
        self.gone = self.gone - {service} if alive else self.gone | {service}
        return False

    # -- simulation --------------------------------------------------------------------------

    def stale_reason(self, t: float | None = None) -> str:
        """Why the robot must hold at time ``t`` (default now), or ``""`` when it may move."""
        t = self.t if t is None else t
        limit = self.config.stale_limit_s
        if self.reference is None or self.fresh.plan is None:
            return FIRST_PLAN
        gone = sorted(self.gone)
        if gone:
            return f"{' and '.join(gone)} gone (liveliness token lost)"
        age = t - self.fresh.plan
        if age > limit + 1e-9:
            return f"plan is {age:.2f} s old (limit {limit:.2f} s)"
        lost = self.fresh.lost  # read once: a start marker (the transport's thread) may clear it between two reads
        if self.config.require_occupancy and lost is not None:
            return f"{lost}: holding until the person is seen again (at rest or reaching)"
        if self.config.require_occupancy and not (self.human_ended and self.fresh.occupancy is not None):
            if self.fresh.occupancy is None:  # a live tracker publishes poses once the person is seen
                return "no occupancy prediction received yet" + (
                    " (the tracker publishes poses once it has seen the person at rest, and during reaches: the robot "
                    "moves once the person is seen)" if "tracker" in self.seen else "")
            age = t - self.fresh.occupancy
            if age > limit + 1e-9:
                return f"occupancy is {age:.2f} s old (limit {limit:.2f} s)"
        return ""

    def step(self, h: float, hold_reason: str | None = None) -> None:
        """Advance the simulation by ``h`` seconds.

        Args:
            h: Step length, seconds (> 0).
            hold_reason: If given, use it instead of :meth:`stale_reason` and the ``guard`` (lock-step mode decides
                once per replanning step; a ROS 2 robot's arm asks the guard before it commands the robot); ``""``
                means move.
        """
        if not (h > 0 and math.isfinite(h)):
            raise ExecutorError(f"step: h must be > 0, got {h}")
        reason = self.stale_reason() if hold_reason is None else hold_reason
        if reason or self.reference is None:
            self.holding, self.reason = True, reason or FIRST_PLAN
            self.qd = np.zeros(self.limits.dof)
        else:
            self.holding, self.reason = False, ""
            advance, at = self._pace(h, self.reference)
            target = at(self.tau + advance)
            vmax = self.limits.velocity * self.config.velocity_scale
            v = (target - self.q) / h
            scale = float(np.max(np.abs(v) / vmax))
            if scale > 1.0:  # the limits slow the arm: the reference advances only as far as the arm can follow
                advance /= scale  # (time scaling), so the arm stays on the path at a bend instead of cutting it
                target = at(self.tau + advance)
                v = (target - self.q) / h
                scale = float(np.max(np.abs(v) / vmax))
                if scale > 1.0:
                    v = v / scale
            q_new = self.limits.clamp(self.q + v * h)
            moves = not np.array_equal(q_new, self.q)  # at rest (at the goal) it closes in on no one: 2 ms of FK spared
            why = self.guard(self.q, q_new) if self.guard is not None and hold_reason is None and moves else ""
            if why:  # the step would close in on the person: the robot and its reference's clock stay
                self.holding, self.reason = True, why
                self.qd = np.zeros(self.limits.dof)
            else:
                self.tau += advance
                self.qd = (q_new - self.q) / h
                self.q = q_new
        self.t += h
        self._update_reached()

    def target_after(self, h: float) -> np.ndarray:
        """``(D,)`` where the reference asks the arm to be ``h`` seconds on (its present place without a plan)."""
        if self.reference is None:
            return self.q.copy()
        advance, at = self._pace(h, self.reference)
        return self.limits.clamp(at(self.tau + advance))

    def _pace(self, h: float, ref: Reference) -> tuple[float, Callable[[float], np.ndarray]]:
        """How far along ``ref`` a step of ``h`` seconds goes, and the reference's lookup for that measure."""
        if self.config.path_per_step > 0:  # the paper authors' pace: a fixed length of the path per step
            return self.config.path_per_step * h / self.config.step_period_s, ref.at_length
        return h, ref.at

    @property
    def remaining(self) -> float:
        """What is left of the reference: seconds, or configuration-space length with ``path_per_step``.

        Once the reference's own clock has run out, what the arm still lags behind its end (the velocity limits
        may hold a joint back): the weighted distance to the last waypoint, or the time it takes at the limits.
        """
        if self.reference is None:
            return 0.0
        ref = self.reference
        gap = ref.goal - self.q
        if self.config.path_per_step > 0:
            left = ref.length - self.tau
            lag = float(np.linalg.norm(gap * (1.0 if self._path_weights is None else self._path_weights)))
        else:
            left = ref.duration - self.tau
            lag = float(np.max(np.abs(gap) / (self.limits.velocity * self.config.velocity_scale)))
        return left if left > 0.0 else (lag if lag > 1e-9 else 0.0)

    def _update_reached(self) -> None:
        if self.reference is None:
            self.reached = False
            return
        self.reached = bool(np.max(np.abs(self.q - self.reference.goal)) <= self.config.goal_tolerance)

    def state(self, tick: int, stamp: float | None = None) -> RobotState:
        """The current state as a RobotState message (``stamp`` default: the core's time)."""
        return RobotState(stamp=self.t if stamp is None else float(stamp), tick=int(tick),
                          joint_names=list(self.limits.joint_names), goal=self.goal, reached=self.reached,
                          holding=self.holding, reason=self.reason, q=self.q.copy(), qd=self.qd.copy())
