"""``foresight eval volumes``: which occupancy volume serves the real human best, in the closed loop.

The predictor's class volumes ``p(x|C_m)`` (:mod:`services.predictor.volumes`: ``paper``, ``spread``,
``demos``, ``timed``) are compared open-loop by ``foresight eval occupancy``; this runs them in the
loop. For each volume, the two experiments with the paper's planner (least penetration of the
predicted occupancy), every run through the four services in lock-step:

* Table I (:mod:`services.experiments.interference`): the robot's one task crosses the human's reach;
  ``demos`` held-out demonstrations x ``seeds`` seeds;
* the goal switch (:mod:`services.experiments.switch`): two tasks, every demonstration of the class
  (``switch_demos``: the first that many) held out in turn.

Each run is scored against the human who was really there: time in contact with the body model,
minimum clearance, and whether the robot reached its goal; the switch also by its settle step.
The paper's own integral cost is not compared across volumes: each volume scores against its own
prediction. The rule that picks a default (:meth:`VolumesResult.choice`): among the volumes with
which the robot reaches its goal in every run and leaves the human's cup for good no later (median
away step, :func:`services.experiments.switch.away_step`) than with ``paper``, the
fewest seconds in contact over all runs; ties by the larger median minimum clearance.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from services.predictor.volumes import VOLUMES

from .interference import InterferenceConfig, run_interference
from .planners import Timing
from .switch import SwitchConfig, run_switch

__all__ = ["VolumesConfig", "VolumeScore", "VolumesResult", "run_volumes"]


@dataclass(frozen=True)
class VolumesConfig:
    """Options of the closed-loop volume comparison."""

    library: str = "synthetic"
    volumes: tuple[str, ...] = VOLUMES
    demos: int = 5
    seeds: int = 10
    switch_demos: int = 0  # 0: every demonstration of the class
    timing: Timing = Timing()
    components: int | None = None
    models_dir: Path = Path("models/experiments")
    work_dir: Path = Path("runs/experiments")


@dataclass(frozen=True)
class VolumeScore:
    """What one volume did to the real human in both experiments (least penetration only).

    Attributes:
        volume: The volume method.
        runs: Runs of Table I + runs of the switch.
        contact_s: Seconds in contact with the body, summed over every run.
        runs_in_contact: Runs with any contact.
        median_min_clearance: Median over every run of its minimum clearance (m).
        time_near_s: Seconds within 5 cm in Table I, summed.
        reached: Runs that reached their goal.
        settle_step: Median settle step of the switch (the step from which the robot keeps its final goal).
        away_step: Median step from which the robot never again goes for the human's cup (never: the run's steps).
        ends_at_human_cup: Switch runs that end going for the human's cup.
        planning_ms: Median planning time of a step.
    """

    volume: str
    runs: int
    contact_s: float
    runs_in_contact: int
    median_min_clearance: float
    time_near_s: float
    reached: int
    settle_step: float
    away_step: float
    ends_at_human_cup: int
    planning_ms: float


@dataclass
class VolumesResult:
    """Every volume's score, and the raw results of its experiments."""

    config: VolumesConfig
    library: str = ""
    scores: list[VolumeScore] = field(default_factory=list)
    raw: dict[str, dict[str, Any]] = field(default_factory=dict)

    def choice(self) -> tuple[str | None, str]:
        """The volume the rule picks (None if none qualifies) and why, in one line."""
        by = {s.volume: s for s in self.scores}
        ref = by.get("paper")
        ok = [s for s in self.scores if s.reached == s.runs
              and (ref is None or math.isnan(ref.away_step) or s.away_step <= ref.away_step)]
        if not ok:
            return None, "no volume reached the goal in every run without leaving the human's cup later than paper"
        best = min(ok, key=lambda s: (round(s.contact_s, 6), -s.median_min_clearance))
        rest = ", ".join(sorted(s.volume for s in self.scores if s not in ok)) or "none"
        return best.volume, (f"{best.volume}: {best.contact_s:.2f} s in contact over {best.runs} runs, median min "
                             f"clearance {best.median_min_clearance:+.3f} m, away step {best.away_step:g} "
                             f"(excluded for missing a goal or leaving the human's cup later than paper: {rest})")

    def lines(self) -> list[str]:
        """A table, one row per volume, then the choice."""
        ran = {len(r["switch_runs"]) for r in self.raw.values()}  # what ran: --switch-demos 2 said "every"
        n = ran.pop() if len(ran) == 1 else self.config.switch_demos
        switch = (f"{n} demonstration{'s' * (n != 1)}" if n else "every demonstration") + (
            " of the class" if self.config.switch_demos == 0 else "")
        out = [f"closed-loop volume comparison ({self.library}): least penetration, Table I "
               f"({self.config.demos} demonstrations x {self.config.seeds} seeds) + the switch ({switch}, each held "
               f"out in turn); scored against the real human",
               f"{'volume':<8}{'runs':>6}{'contact s':>11}{'runs touching':>15}{'median min clear.':>19}"
               f"{'near s':>8}{'reached':>9}{'settle':>8}{'away':>6}{'at human cup':>14}{'plan ms':>9}"]
        for s in self.scores:
            out.append(f"{s.volume:<8}{s.runs:>6}{s.contact_s:>11.2f}{s.runs_in_contact:>15}"
                       f"{s.median_min_clearance:>+18.3f}m{s.time_near_s:>8.2f}{s.reached:>5} of {s.runs:<3}"
                       f"{s.settle_step:>6g}{s.away_step:>6g}{s.ends_at_human_cup:>14}{s.planning_ms:>9.0f}")
        best, why = self.choice()
        out.append(f"rule's choice: {why}" if best else f"rule's choice: none ({why})")
        return out

    def to_json(self) -> dict[str, Any]:
        """``scores`` (one object per volume), ``choice`` and ``why``, and each volume's raw results."""
        best, why = self.choice()
        return {"library": self.library, "config": {k: (str(v) if isinstance(v, Path) else v)
                                                   for k, v in dataclasses.asdict(self.config).items()},
                "scores": [dataclasses.asdict(s) for s in self.scores], "choice": best, "why": why,
                "raw": self.raw}


def run_volumes(cfg: VolumesConfig, progress: Callable[[str], None] = print, compile: bool = True) -> VolumesResult:
    """Run Table I and the switch with each volume (least penetration only) and score them."""
    unknown = [v for v in cfg.volumes if v not in VOLUMES]
    if unknown or not cfg.volumes:
        raise ValueError(f"volumes must be some of {', '.join(VOLUMES)}, got {', '.join(cfg.volumes) or 'none'}")
    result = VolumesResult(cfg)
    common = {"library": cfg.library, "timing": cfg.timing, "components": cfg.components,
              "models_dir": cfg.models_dir, "work_dir": cfg.work_dir}
    for volume in cfg.volumes:
        progress(f"volume {volume}:")
        table = run_interference(InterferenceConfig(demos=cfg.demos, seeds=cfg.seeds, volume=volume,
                                                    variants=("least_penetration",), **common),
                                 progress, compile=compile)
        switch = run_switch(SwitchConfig(demos=cfg.switch_demos, volume=volume, methods=("prediction",), **common),
                            progress, compile=compile)
        result.library = table.library
        lp = [r for r in table.runs if r.planner == "least_penetration"]
        sw = switch.runs
        clear = [r.min_clearance for r in lp] + [r.min_clearance for r in sw]
        contact = [r.time_in_contact for r in lp] + [r.time_in_contact for r in sw]
        plan = [r.planning_ms for r in lp] + [r.planning_ms for r in sw]
        result.scores.append(VolumeScore(
            volume=volume, runs=len(lp) + len(sw), contact_s=float(np.sum(contact)),
            runs_in_contact=int(np.sum(np.asarray(contact) > 0)), median_min_clearance=float(np.median(clear)),
            time_near_s=float(sum(r.time_near for r in lp)),
            reached=sum(r.reached_step is not None for r in lp) + sum(r.reached_step is not None for r in sw),
            settle_step=switch.median_settle("prediction"), away_step=switch.median_away("prediction"),
            ends_at_human_cup=switch.conflicts("prediction"),
            planning_ms=float(np.median(plan))))
        result.raw[volume] = {"interference_runs": [dataclasses.asdict(r) for r in lp],
                              "switch_runs": [dataclasses.asdict(r) for r in sw]}
        progress("  " + result.lines()[2 + len(result.scores) - 1])
    return result
