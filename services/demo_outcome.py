"""What a demo run did to the human: interference with the prediction, contact with the real body, a verdict.

:func:`measure_run` scores one run's executed trajectory the way the experiments do
(:mod:`services.experiments.measures`): the interference with a reference prediction (the paper's
Table I: penetration of the predicted occupancy integrated over time) and the clearance between the
robot's spheres and the real human's body capsules at every executed state (contact = clearance <= 0).
:func:`verdict` says in words whether ``--compare`` showed the paper's point: the prediction planner
interferes less and touches the human less than both baselines. :func:`novelty_counts` counts the poses the
predictor's novelty test called unlike every class (``ClassPosterior.familiar`` in the run's log): the summary's
"recognised at the end" names the most probable class, which a motion no class explains has too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from services.experiments.measures import contact_summary, interference, postures_at
from shared.clearance import body_clearance
from shared.protocol import ClassPosterior, HumanPose, OccupancyGrid, ProtocolError, RobotState, decode
from shared.recording.reader import read_log
from shared.runtime import UserError
from shared.scene import Scene

__all__ = ["Outcome", "measure_run", "reached_after_last", "verdict", "outcome_lines", "cut_words", "novelty_counts",
           "novelty_lines", "INTERFERENCE_EQUAL"]

INTERFERENCE_EQUAL = 0.005
"""Interferences nearer than this are a tie: the verdict prints them to two decimals, and a real-time run's 0.001 /
0.001 / 0.000 (occupancy-seconds) read "its interference was not the lowest: interference with the predicted motion
0.00 against 0.00, 0.00"."""


@dataclass
class Outcome:
    """One planner's run, measured.

    Attributes:
        planner: ``prediction``, ``current occupancy`` or ``no human cost``.
        interference: Penetration of the reference prediction integrated over the run (probability-voxels x s).
        contact_s: Seconds the robot overlapped the real human's body.
        near_s: Seconds the robot was within :data:`~services.experiments.measures.NEAR_M` (5 cm) of it.
        min_clearance_m: Smallest robot-human clearance (m; negative: overlap).
        switch_step, reached_step: As in the run's summary (None: never).
        chosen_goal_per_step: The goal chosen at each replanning step.
        stamps: ``(N,)`` times of the executed states (s, the run's clock).
        ee_path: ``(N, 3)`` end-effector positions of the executed states (scene frame).
        clearance: ``(N,)`` robot-human clearance at each executed state (m).
        mcap_path: The run's log.
        cut_short: How the run was cut short (``interrupted after 9 of 20 steps``), "" when it ran to its end.
        unit: What ``switch_step``, ``reached_step`` and ``chosen_goal_per_step`` count: lock-step's steps or a
            real-time run's plans.
        plan_t_s: ``(S,)`` seconds into the run each plan of ``chosen_goal_per_step`` was made (the run's summary;
            None: one a replanning period apart, as in lock-step).
        unfamiliar: Poses the predictor's novelty test called unlike every class (:func:`novelty_counts`).
        judged: Poses whose class posterior the run's log holds (what ``unfamiliar`` is out of).
        reached_t_s: When the goal was reached (s into the run; None: never).
        reached_after: Reached after the table's last step (lock-step: the robot ends its last plan then, and
            ``reached_step`` counts on past it, "reached step 22" of a 20-step run; a review): said by its time.
    """

    planner: str
    interference: float
    contact_s: float
    near_s: float
    min_clearance_m: float
    switch_step: int | None
    reached_step: int | None
    chosen_goal_per_step: list[str]
    stamps: np.ndarray = field(repr=False)
    ee_path: np.ndarray = field(repr=False)
    clearance: np.ndarray = field(repr=False)
    mcap_path: str | None = None
    cut_short: str = ""
    unit: str = "step"
    plan_t_s: np.ndarray | None = field(default=None, repr=False)
    unfamiliar: int = 0
    judged: int = 0
    reached_t_s: float | None = None
    reached_after: bool = False

    def to_json(self) -> dict[str, Any]:
        """The scalar fields (the arrays stay out of ``--json``)."""
        return {"planner": self.planner, "interference_cost": self.interference, "contact_s": self.contact_s,
                "near_s": self.near_s,
                "min_clearance_m": self.min_clearance_m if math.isfinite(self.min_clearance_m) else None,
                "switch_step": self.switch_step, "reached_step": self.reached_step,
                "chosen_goal_per_step": self.chosen_goal_per_step, "mcap_path": self.mcap_path,
                "cut_short": self.cut_short, "unfamiliar_poses": self.unfamiliar, "poses_judged": self.judged,
                "reached_t_s": self.reached_t_s, "reached_after_last_step": self.reached_after}


def measure_run(planner: str, states: list[RobotState], poses: list[HumanPose], reference: OccupancyGrid | None,
                robot: Any, scene: Scene, summary: Any) -> Outcome:
    """Measure one run.

    Args:
        planner: Its name.
        states: The executed robot states (any order; sorted by stamp here).
        poses: The human's poses streamed during the run (their stamps share the states' clock).
        reference: The prediction to score interference against (None: 0).
        robot: The robot model (:class:`shared.robot.PR2` of the scene).
        scene: The run's scene (places the human as the predictor does).
        summary: The run's :class:`services.scenario.Summary`.
    """
    import torch

    states = sorted(states, key=lambda st: st.stamp)
    t = np.array([st.stamp for st in states], dtype=np.float64)
    q = np.array([st.q for st in states], dtype=np.float64).reshape(len(states), int(robot.lower.shape[0]))
    cost = interference(robot, q, t, reference) if reference is not None and len(q) else 0.0
    if len(q) and poses:
        clearance = body_clearance(robot, q, postures_at(poses, t, scene))
    else:
        clearance = np.full(len(q), np.inf)
    contact = contact_summary(clearance, t)
    ee = (robot.end_effector(torch.as_tensor(q, dtype=robot.lower.dtype)).detach().cpu().numpy()[..., :3, 3]
          if len(q) else np.zeros((0, 3)))
    return Outcome(planner, float(cost), contact.time_in_contact, contact.time_near, contact.min_clearance,
                   summary.switch_step, summary.reached_step, list(summary.chosen_goal_per_step), t, ee, clearance,
                   summary.mcap_path, str(summary.extra.get("cut_short", "")), summary.unit,
                   np.array([float(s["t_s"]) for s in summary.steps], dtype=np.float64),
                   *novelty_counts(summary.mcap_path), summary.reached_t_s, reached_after_last(summary))


def reached_after_last(summary: Any) -> bool:
    """Whether a run's goal was reached after its table's last step (``reached_step`` past every row's)."""
    last = max((s["step"] for s in summary.steps), default=None)
    return summary.reached_step is not None and last is not None and summary.reached_step > last


def _reached_cell(o: Outcome) -> str:
    """The table's "reached" cell: the step, or after the last one its time (its step number is past the run's)."""
    if o.reached_after and o.reached_t_s is not None:
        return f"after ({o.reached_t_s:.1f} s)"
    return "-" if o.reached_step is None else str(o.reached_step)


def novelty_counts(mcap_path: str | None) -> tuple[int, int]:
    """``(unfamiliar, judged)``: the class posteriors in a run's log that the predictor called unfamiliar, of all.

    A log that is missing or not an MCAP file counts ``(0, 0)``; a message that does not decode is not counted.
    """
    if not mcap_path:
        return 0, 0
    try:
        lf = read_log(mcap_path, keep=lambda ch: ch.schema_name == "foresight.ClassPosterior"
                      and ch.message_encoding == "msgpack")
    except (UserError, OSError):
        return 0, 0
    familiar = []
    for m in lf.messages:
        try:
            familiar.append(decode(m.data, ClassPosterior).familiar)
        except ProtocolError:
            continue
    return familiar.count(False), len(familiar)


def novelty_lines(outcomes: list[Outcome]) -> list[str]:
    """A line per run whose predictor called poses unlike every class (none when no pose was)."""
    out = []
    for o in (o for o in outcomes if o.unfamiliar):
        run = f" ({o.planner} run)" if len(outcomes) > 1 else ""
        out.append(f"novelty{run}: the predictor called {o.unfamiliar} of {o.judged} poses unlike every class (its "
                   "novelty test): the class it names then is only the least unlikely. Its threshold suits the sensor "
                   "the model was calibrated for (foresight train --sensor-noise-m; the demo's: --keypoint-noise-m): "
                   "a known reach seen through a noisier one falls below it at most poses (docs/prediction.md, "
                   "'A noisy sensor')")
    return out


def _kept_further(main: Outcome, other: Outcome) -> bool:
    """Whether ``main`` kept further from the real human than ``other``.

    Less contact; on equal contact (neither touched, say), less time within 5 cm; on equal time within 5 cm, a
    larger smallest clearance. (An ``or`` of the last two let 1 mm more clearance outweigh 12x the time near.)
    """
    if not math.isclose(main.contact_s, other.contact_s, abs_tol=1e-9):
        return main.contact_s < other.contact_s
    if not math.isclose(main.near_s, other.near_s, abs_tol=1e-9):
        return main.near_s < other.near_s
    return main.min_clearance_m > other.min_clearance_m


def verdict(outcomes: list[Outcome]) -> str:
    """Whether the first (the prediction planner) interfered and came near the human less than every other, in words.

    Against each baseline, contact decides; where the contact ties (neither touched the human, say), the
    time within 5 cm and the smallest clearance tell them apart, and the verdict says so. The interference must
    be lower, or tie (within :data:`INTERFERENCE_EQUAL`: neither path entered the predicted volume, as a real-time
    run's final prediction, the reach over, can give), which the verdict says too.
    """
    main, others = outcomes[0], outcomes[1:]
    if not others:
        return ""
    if cut := [o for o in outcomes if o.cut_short]:  # a part of a run against a whole one says nothing
        return (f"none: the {' and '.join(f'{o.planner} run was {o.cut_short}' for o in cut)}, so its numbers are "
                "of a part of the run; let --compare run to its end for a verdict")
    names = " and ".join(o.planner for o in others)
    level = [o.planner for o in others if abs(main.interference - o.interference) < INTERFERENCE_EQUAL]
    less_interference = all(main.interference < o.interference or o.planner in level for o in others)
    further = all(_kept_further(main, o) for o in others)

    def against(values: list[str]) -> str:
        return f"{values[0]} against {', '.join(values[1:])}"

    touched = any(o.contact_s > 0 for o in outcomes)
    contact = (f"touched the real human {against([f'{o.contact_s:.1f} s' for o in outcomes])}" if touched
               else "no planner touched the real human")
    body = (f"interference with the predicted motion {against([f'{o.interference:.2f}' for o in outcomes])}; "
            f"{contact}; within 5 cm of it {against([f'{o.near_s:.1f} s' for o in outcomes])}; closest "
            f"{against([f'{o.min_clearance_m * 100:.0f} cm' for o in outcomes])}")
    ties = [o.planner for o in others if math.isclose(main.contact_s, o.contact_s, abs_tol=1e-9)]
    if touched and ties:
        tie = ("did not touch the human either" if main.contact_s == 0 else
               "touched the human as long as the prediction planner")
        body += (f" ({' and '.join(ties)} {tie}: there the time within 5 cm and the closest approach tell them "
                 "apart)")
    if level:  # "not the lowest" of a 0.00 against 0.00 said the prediction planner did worse (a real-time run)
        body += (f" ({' and '.join(level)} interfered with the predicted motion as little: the nearness to the real "
                 "human tells them apart)")
    if less_interference and further:
        return f"shown, against {names}: {body}"
    missed = [what for what, ok in (("its interference was not the lowest", less_interference),
                                    ("it did not stay further from the human", further)) if not ok]
    return (f"not shown in this run ({' and '.join(missed)}): {body}. "
            "docs/experiments.md, 'Across the robot's pace': prediction pays off when the robot is slow "
            "relative to the human")


def not_run(outcomes: list[Outcome], planned: list[str]) -> list[str]:
    """The planners of ``planned`` with no outcome (a ``--compare`` run interrupted before they ran)."""
    return [name for name in planned if name not in {o.planner for o in outcomes}]


def cut_words(outcomes: list[Outcome], planned: list[str], failed: bool = False) -> str:
    """What of the run is missing, for the picture's title: the planners cut short, and those not run at all.

    ``failed``: a service of one failed (a crash at start was called an interruption); else the run was interrupted.
    """
    missing = not_run(outcomes, planned)
    return "; ".join([f"{o.planner} {o.cut_short}" for o in outcomes if o.cut_short]
                     + ([f"{' and '.join(missing)} not run ({'a service failed' if failed else 'interrupted'})"]
                        if missing else []))


def outcome_lines(outcomes: list[Outcome], against: str = "the prediction planner's final prediction",
                  planned: list[str] | None = None, failed: bool = False) -> list[str]:
    """The comparison table and its verdict.

    ``against``: what the interference is scored against; ``planned``: the planners the run was to compare
    (``--compare``'s), when some did not run (interrupted, or ``failed``: a service of one failed).
    """
    unit = outcomes[0].unit if outcomes else "step"
    out = [*novelty_lines(outcomes), "",
           f"comparison (interference: the paper's Table I measure against {against}; contact: overlap with the "
           "real human's body):",
           f"  {'planner':<20}{'interference':>13}{'contact s':>11}{'within 5 cm s':>15}{'min clearance m':>17}"
           f"{'switch ' + unit:>13}{'reached ' + unit:>17}"]
    for o in outcomes:
        sw = "-" if o.switch_step is None else str(o.switch_step)
        re = _reached_cell(o)
        clear = f"{o.min_clearance_m:+.3f}" if math.isfinite(o.min_clearance_m) else "-"
        name = f"{o.planner} *" if o.cut_short else o.planner
        out.append(f"  {name:<20}{o.interference:>13.3f}{o.contact_s:>11.2f}{o.near_s:>15.2f}{clear:>17}{sw:>13}"
                   f"{re:>17}")
    out += [f"  * {o.planner}: {o.cut_short}" for o in outcomes if o.cut_short]
    text = verdict(outcomes)
    missing = not_run(outcomes, planned or [])
    if missing:  # Ctrl-C between the planners: "one planner, run --compare" was said to a --compare run
        names = " and ".join(missing)  # a crash at start was called an interruption
        out.append(f"not compared: {names} did not run to an outcome (a service failed: see the lines above)"
                   if failed else f"not compared: the run was interrupted before {names} ran")
    elif text:
        out.append(f"verdict: {text}")
    elif len(outcomes) == 1 and not outcomes[0].cut_short:  # one row says nothing of what prediction changes
        out.append("one planner, nothing to compare with: `foresight demo --compare` (make demo "
                   "DEMO_ARGS=--compare) runs the same scenario with the current occupancy and with no human cost, "
                   "and says whether predicting the human kept the robot further from them")
    return out
