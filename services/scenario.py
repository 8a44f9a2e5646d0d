"""The two-cup scenario without Zenoh: the human's demonstration, its prediction model, the run's summary.

Which demonstration the human performs, the prediction model it is observed with (trained without
that demonstration, cached), and the summary of a run.

Used by ``foresight demo`` (processes over Zenoh) and by the integration tests (services in-process).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from services.experiments.measures import interference
from shared.library import Demonstration, MotionLibrary
from shared.protocol import ClassPosterior, Message, OccupancyGrid, Plan, RobotState
from shared.runtime import UserError
from shared.scene import Scene

__all__ = ["Scenario", "choose_demonstration", "model_for", "RunRecorder", "Summary", "summarise",
           "DEFAULT_HUMAN_CLASS"]

log = logging.getLogger("foresight.scenario")

DEFAULT_HUMAN_CLASS = "red_cup"
"""The human reaches for the red cup (the paper's Fig. 8); the robot plans for both cups."""


@dataclass(frozen=True)
class Scenario:
    """What the human does in a run.

    Attributes:
        demo: The demonstration the replayer streams (held out of the model's training data).
        class_index: Its index within its class (the replayer's ``--indices``).
        samples_per_tick: Poses per replanning step so the motion spans ``steps`` steps.
    """

    demo: Demonstration
    class_index: int
    samples_per_tick: int


def choose_demonstration(library: MotionLibrary, steps: int, seed: int, human_class: str = "") -> Scenario:
    """Pick the demonstration the human performs: a seeded random one of ``human_class``.

    Args:
        library: The motion library.
        steps: Replanning steps of the run; the motion is spread over them (the paper: 20 steps).
        seed: Seed of the choice.
        human_class: Class name or index (``""``: :data:`DEFAULT_HUMAN_CLASS` if the library has it,
            else the last class).

    Raises:
        UserError: Unknown class.
    """
    names = list(library.class_names)
    if not human_class:
        label = names.index(DEFAULT_HUMAN_CLASS) if DEFAULT_HUMAN_CLASS in names else len(names) - 1
    elif human_class in names:
        label = names.index(human_class)
    elif human_class.isdigit() and int(human_class) < len(names):
        label = int(human_class)
    else:
        raise UserError(f"--human-class {human_class!r}: not a class of {library.source} ({', '.join(names)})")
    demos = library.by_class(label)
    if not demos:
        raise UserError(f"library {library.source}: class {names[label]} has no valid demonstration")
    k = int(np.random.default_rng(seed).integers(len(demos)))
    demo = demos[k]
    return Scenario(demo=demo, class_index=demo.index, samples_per_tick=max(1, math.ceil(demo.n_samples / steps)))


def _library_digest(library: MotionLibrary) -> str:
    h = hashlib.sha256()
    h.update(json.dumps(list(library.class_names)).encode())
    for d in library.demos:
        h.update(np.ascontiguousarray(d.features, dtype=np.float64).tobytes())
        h.update(str(d.label).encode())
    return h.hexdigest()[:16]


def model_for(library: MotionLibrary, scene: Scene, held_out: Demonstration | Sequence[Demonstration],
              models_dir: Path, components: int | None = None, progress: bool = True,
              fit_cache: dict[str, Any] | None = None) -> Path:
    """The prediction model for a run: trained on ``library`` without ``held_out``, cached in ``models_dir``.

    The cache key covers the library's data, the held-out demonstrations, the scene and the training
    options, so a changed library, scene or trainer default never reuses a stale model.

    Args:
        library: The motion library.
        scene: The scene the swept volumes are placed in.
        held_out: The demonstration(s) left out of the training data.
        models_dir: Cache directory.
        components: Gaussians per class (None: the trainer's default).
        progress: Show progress bars while training.
        fit_cache: Shared fitted class mixtures (``train_model``'s ``fit_cache``): with one model per
            held-out demonstration, only the held-out demonstration's class is refitted.

    Returns:
        Path of the model file (trained now if it was not cached).
    """
    from services.predictor.model import MODEL_VERSION
    from services.predictor.train import TrainConfig, train_model

    cfg = TrainConfig()
    if components is not None:
        from dataclasses import replace

        cfg = replace(cfg, gmm=replace(cfg.gmm, n_components=components))
    out = [held_out] if isinstance(held_out, Demonstration) else list(held_out)
    left = sorted((d.label, d.index) for d in out)
    key = hashlib.sha256(json.dumps([_library_digest(library), left, repr(scene), repr(cfg),
                                     MODEL_VERSION]).encode()).hexdigest()[:12]
    path = Path(models_dir) / f"demo-{scene.name}-{key}.npz"
    if path.is_file():
        log.info("using cached model %s", path)
        return path
    skip = set(left)
    demos = [d for d in library.demos if (d.label, d.index) not in skip]
    model = train_model(library, scene, cfg, demos=demos, progress=progress, fit_cache=fit_cache)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.npz")
    model.save(tmp)
    tmp.replace(path)
    return path


class RunRecorder:
    """Collects what a run publishes (thread-safe; fed by a subscriber, no Zenoh in here)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.plans: list[Plan] = []
        self.states: list[RobotState] = []
        self.final_occupancy: OccupancyGrid | None = None
        self.posteriors: dict[int, ClassPosterior] = {}

    def on_message(self, msg: Message) -> None:
        """Feed one received message."""
        with self._lock:
            if isinstance(msg, Plan):
                self.plans.append(msg)
            elif isinstance(msg, RobotState):
                self.states.append(msg)
            elif isinstance(msg, OccupancyGrid):
                if self.final_occupancy is None or (msg.tick, msg.index) >= (self.final_occupancy.tick,
                                                                            self.final_occupancy.index):
                    self.final_occupancy = msg
            elif isinstance(msg, ClassPosterior):
                self.posteriors[msg.tick] = msg

    def snapshot(self) -> tuple[list[Plan], list[RobotState], OccupancyGrid | None, dict[int, ClassPosterior]]:
        """Copies of what was recorded so far."""
        with self._lock:
            return list(self.plans), list(self.states), self.final_occupancy, dict(self.posteriors)


@dataclass
class Summary:
    """The result of a run, as ``foresight demo`` prints it (``--json``: :meth:`to_json`)."""

    steps: list[dict[str, Any]]
    chosen_goal_per_step: list[str]
    switch_step: int | None
    interference_cost: float
    mcap_path: str | None
    reached: bool
    reached_step: int | None
    human_class: str
    recognised_class: str | None
    goal_names: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (keys steps, chosen_goal_per_step, switch_step, interference_cost, mcap_path, ...)."""
        out = {"steps": self.steps, "chosen_goal_per_step": self.chosen_goal_per_step, "switch_step": self.switch_step,
               "interference_cost": self.interference_cost, "mcap_path": self.mcap_path, "reached": self.reached,
               "reached_step": self.reached_step, "human_class": self.human_class,
               "recognised_class": self.recognised_class, "goal_names": self.goal_names}
        out.update(self.extra)
        return out

    def lines(self) -> list[str]:
        """Human-readable table."""
        names = self.goal_names
        head = f"{'step':>4}  {'chosen':<12}" + "".join(f"{'cost ' + n:>16}" for n in names) + f"{'plan ms':>9}"
        out = [head]
        for s in self.steps:
            costs = "".join(f"{s['cost_total'].get(n, float('nan')):>16.3f}" for n in names)
            out.append(f"{s['step']:>4}  {s['chosen']:<12}{costs}{s['planning_ms']:>9.0f}")
        out.append(f"switch step: {self.switch_step if self.switch_step is not None else 'none (never switched)'}")
        when = f", step {self.reached_step}" if self.reached_step is not None else ""
        out.append(f"goal reached: {'yes' + when if self.reached else 'no'}")
        out.append(f"human class: {self.human_class}; recognised at the end: {self.recognised_class}")
        out.append(f"interference cost of the executed trajectory (final prediction): {self.interference_cost:.4f}")
        out.append(f"MCAP log: {self.mcap_path}")
        rows = self.extra.get("comparison")
        if rows:
            out.append("")
            out.append("comparison (interference with the final prediction of the paper's method, as in its Table I):")
            out.append(f"  {'planner':<20}{'interference':>13}{'switch step':>13}{'reached step':>14}")
            for r in rows:
                sw = "-" if r["switch_step"] is None else str(r["switch_step"])
                re = "-" if r["reached_step"] is None else str(r["reached_step"])
                out.append(f"  {r['planner']:<20}{r['interference_cost']:>13.4f}{sw:>13}{re:>14}")
        return out


def summarise(plans: list[Plan], states: list[RobotState], final_occupancy: OccupancyGrid | None,
              posteriors: dict[int, ClassPosterior], robot: Any, human_class: str, mcap_path: str | None,
              goal_tolerance: float = 0.02) -> Summary:
    """Summarise a run from its messages.

    Args:
        plans: Plans in arrival order (one per step; duplicates of a tick: the last wins).
        states: Executed robot states.
        final_occupancy: The last occupancy prediction (None: interference cost 0).
        posteriors: ClassPosterior by tick.
        robot: Robot model (sphere centres) for the interference cost.
        human_class: The true class of the observed demonstration.
        mcap_path: The run's log.
        goal_tolerance: Joint-space tolerance of "goal reached".
    """
    by_tick: dict[int, Plan] = {}
    for p in plans:
        by_tick[p.tick if p.tick >= 0 else len(by_tick)] = p
    ordered = [by_tick[t] for t in sorted(by_tick)]
    steps, chosen = [], []
    for p in ordered:
        name = p.goal_names[p.chosen]
        chosen.append(name)
        steps.append({"step": p.step, "tick": p.tick, "chosen": name, "planning_ms": p.planning_ms,
                      "occupancy_tick": p.occupancy_tick,
                      "cost_total": {n: float(c) for n, c, v in zip(p.goal_names, p.cost_total, p.valid, strict=True)
                                     if v},
                      "cost_human": {n: float(c) for n, c, v in zip(p.goal_names, p.cost_human, p.valid, strict=True)
                                     if v}})
    switch = None
    for i in range(1, len(chosen)):
        if chosen[i] != chosen[i - 1]:
            switch = steps[i]["step"]
    states = sorted(states, key=lambda s: s.stamp)
    q = np.array([s.q for s in states]) if states else np.zeros((0, 0))
    stamps = np.array([s.stamp for s in states])
    cost = interference(robot, q, stamps, final_occupancy) if final_occupancy is not None and len(q) else 0.0
    reached_states = [s for s in states if s.reached]
    reached_step = reached_states[0].tick if reached_states and reached_states[0].tick >= 0 else None
    recognised = None
    if posteriors:
        last = posteriors[max(posteriors)]
        recognised = last.class_names[int(np.argmax(last.posterior))]
    goal_names = list(ordered[-1].goal_names) if ordered else []
    return Summary(steps=steps, chosen_goal_per_step=chosen, switch_step=switch, interference_cost=cost,
                   mcap_path=mcap_path, reached=bool(reached_states), reached_step=reached_step,
                   human_class=human_class, recognised_class=recognised, goal_names=goal_names)
