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
import zipfile
import zlib
from collections.abc import Callable, MutableMapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from services.adopted_plans import adopted
from services.demo_inputs import DEFAULT_HUMAN_CLASS, human_label
from services.executor.config import is_separation_hold
from services.experiments.measures import interference
from services.run_table import step_entry, table_header, table_row
from shared.belief import recognised_class
from shared.library import FEATURE_NAMES, Demonstration, MotionLibrary
from shared.protocol import ClassPosterior, OccupancyGrid, Plan, RobotState
from shared.runtime import UserError
from shared.scene import Scene

__all__ = ["Scenario", "choose_demonstration", "model_for", "Summary", "summarise", "DEFAULT_HUMAN_CLASS",
           "belief", "posterior_for"]

log = logging.getLogger("foresight.scenario")


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
    label = human_label(names, human_class, str(library.source))
    demos = library.by_class(label)
    if not demos:
        raise UserError(f"library {library.source}: class {names[label]} has no valid demonstration")
    k = int(np.random.default_rng(seed).integers(len(demos)))
    demo = demos[k]
    return Scenario(demo=demo, class_index=demo.index, samples_per_tick=max(1, math.ceil(demo.n_samples / steps)))


def _library_digest(library: MotionLibrary) -> str:
    """A digest of the library's classes, values and labels, and of its feature names where not the paper's 12.

    A 17-column CSV and a wide .npz of the same numbers shared a key, and a model; the paper's 12 keep the keys of
    the models cached before.
    """
    h = hashlib.sha256()
    h.update(json.dumps(list(library.class_names)).encode())
    if tuple(library.feature_names) != FEATURE_NAMES:
        h.update(json.dumps(list(library.feature_names)).encode())
    for d in library.demos:
        h.update(np.ascontiguousarray(d.features, dtype=np.float64).tobytes())
        h.update(str(d.label).encode())
    return h.hexdigest()[:16]


def _damage(path: Path) -> str:
    """What is wrong with a cached model file ('' if nothing): every member's CRC is checked, not the contents."""
    try:
        with zipfile.ZipFile(path) as z:
            bad = z.testzip()
    except (OSError, zipfile.BadZipFile, EOFError, ValueError, zlib.error) as exc:  # zlib: a member's bad stream
        return f"{type(exc).__name__}: {exc}"
    return f"{bad} fails its CRC" if bad else ""


def model_for(library: MotionLibrary, scene: Scene, held_out: Demonstration | Sequence[Demonstration],
              models_dir: Path, components: int | None = None, progress: bool = True,
              fit_cache: MutableMapping[str, Any] | None = None, volume: str | None = None,
              on_train: Callable[[Path], None] | None = None, sensor_noise_m: float = 0.0,
              time_from: str = "recording") -> Path:
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
        volume: Volume method (``foresight train --volume``; None: the trainer's default).
        on_train: Called with the model's path before it is trained (not when it is cached): a caller says why
            the next minute passes.
        sensor_noise_m: The keypoint noise the novelty threshold is calibrated for (``foresight train
            --sensor-noise-m``; 0: the features as recorded). In the key: another noise is another model.
        time_from: Where each training demonstration's time starts (``foresight train --time-from``): ``tracker``
            for a human through the tracker, whose reach starts where its rule says. In the key where not the default.

    Returns:
        Path of the model file (trained now if it was not cached).
    """
    from dataclasses import replace

    from services.predictor.model import MODEL_VERSION
    from services.predictor.train import TrainConfig, train_model

    cfg = TrainConfig()
    if components is not None:
        cfg = replace(cfg, gmm=replace(cfg.gmm, n_components=components))
    if volume is not None:
        cfg = replace(cfg, volume=volume)
    if sensor_noise_m:  # in repr(cfg), the key, only where set: the models cached before keep their keys
        cfg = replace(cfg, sensor_noise_m=sensor_noise_m)
    cfg = replace(cfg, time_from=time_from)  # in repr(cfg) only where not "recording"
    out = [held_out] if isinstance(held_out, Demonstration) else list(held_out)
    left = sorted((d.label, d.index) for d in out)
    key = hashlib.sha256(json.dumps([_library_digest(library), left, repr(scene), repr(cfg),
                                     MODEL_VERSION]).encode()).hexdigest()[:12]
    path = Path(models_dir) / f"demo-{scene.name}-{key}.npz"
    if path.is_file():
        damage = _damage(path)
        if not damage:
            log.info("using cached model %s", path)
            return path
        log.warning("cached model %s is damaged (%s): training it again", path, damage)
    if on_train is not None:
        on_train(path)
    skip = set(left)
    demos = [d for d in library.demos if (d.label, d.index) not in skip]
    model = train_model(library, scene, cfg, demos=demos, progress=progress, fit_cache=fit_cache)
    model.save(path)  # atomic_write: a temporary name of its own per writer, removed if interrupted before the rename
    return path


def _at(entry: dict[str, Any]) -> str:
    return f"{entry['step']} (t = {entry['t_s']:.2f} s)"


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
    reached_t_s: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    scored_against: str = "final prediction"
    recognised_p: float | None = None  # the recognised class's probability in the last posterior
    recognised_flat: bool = False  # the last posterior names no class (shared.belief): recognised_class its argmax
    recognised_index: int | None = None  # the pose that posterior was made after
    separation_held_s: float = 0.0  # real time: seconds the separation guard held the robot (docs/executor.md)
    separation_at_end: bool = False  # and whether it held the robot at the run's end
    left_goal: dict[str, Any] | None = None  # not reached: a goal it reached earlier and left ({goal, reached_t_s,
    # left_t_s}: the robot turned to another, or was sent back later)
    unit: str = "step"  # what the rows and the steps named count: lock-step's ticks, or a real-time run's plans
    scored: bool = True  # False: no occupancy grid to score the interference against (the cost is 0 by default)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (keys steps, chosen_goal_per_step, switch_step, interference_cost, mcap_path, ...)."""
        out = {"steps": self.steps, "chosen_goal_per_step": self.chosen_goal_per_step, "switch_step": self.switch_step,
               "interference_cost": self.interference_cost, "mcap_path": self.mcap_path, "reached": self.reached,
               "reached_step": self.reached_step, "human_class": self.human_class,
               "recognised_class": self.recognised_class, "goal_names": self.goal_names,
               "reached_t_s": self.reached_t_s, "recognised_p": self.recognised_p,
               "recognised_index": self.recognised_index, "separation_held_s": self.separation_held_s,
               "separation_at_end": self.separation_at_end, "left_goal": self.left_goal, "unit": self.unit,
               "interference_scored": self.scored,  # lock-step's reached_step counts on past the last row's
               "reached_after_last_step": self.reached_step is not None and bool(self.steps)
               and self.reached_step > max(s["step"] for s in self.steps)}
        out.update(self.extra)
        return out

    def lines(self, table: bool = True) -> list[str]:
        """Human-readable summary.

        Args:
            table: Start with the table of steps (False when it was printed live, row by row).

        Returns:
            The lines: the table, then the switch, the goal, the recognition, the interference cost, the log.
        """
        names = self.goal_names
        out = [table_header(names, self.unit), *(table_row(s, names, s.get("belief", "")) for s in self.steps)] \
            if table else []
        by_step = {s["step"]: s for s in self.steps}
        if self.switch_step is None:
            out.append(f"switch {self.unit}: none (never switched)")
        else:
            entry = by_step.get(self.switch_step)
            out.append(f"switch {self.unit}: {_at(entry) if entry is not None else self.switch_step}")
        reached = "no"
        if self.reached:
            reached = "yes"
            # past the table's last step (the tick counts on while the robot ends its plan): "during step 20" of 0..9
            late = self.reached_step is not None and self.reached_step > max(by_step, default=self.reached_step)
            if self.reached_step is not None:
                reached += f", after the last {self.unit} ({max(by_step)})" if late else \
                    f", during {self.unit} {self.reached_step}"
            if self.reached_t_s is not None:
                reached += f", at t = {self.reached_t_s:.2f} s" if late else f" (t = {self.reached_t_s:.2f} s)"
        if not self.reached and self.left_goal is not None:
            g = self.left_goal
            reached += (f" (it reached {g['goal']} at t = {g['reached_t_s']:.2f} s and left it at "
                        f"{g['left_t_s']:.2f} s, turned to another goal)")
        out.append(f"goal reached: {reached}")
        if self.separation_held_s > 0:
            out.append(f"separation guard: held the robot {self.separation_held_s:.2f} s (a step would have brought it "
                       "nearer the person than separation.stop_m; docs/executor.md)")
        at = (f" (p {self.recognised_p:.2f}, after pose {self.recognised_index})"  # an interrupted run's belief
              if self.recognised_p is not None else "")                        # differed from its last row's
        named = f"none (flat; most probable {self.recognised_class})" if self.recognised_flat else self.recognised_class
        out.append(f"human class: {self.human_class}; recognised at the end: {named}{at}")
        if self.scored:
            out.append(f"interference cost of the executed trajectory ({self.scored_against}): "
                       f"{self.interference_cost:.4f}")
        else:  # it printed "(final prediction): 0.0000" for a log with no grid at all (a review)
            out.append("interference cost of the executed trajectory: not scored (no occupancy prediction was logged)")
        out.append(f"MCAP log: {self.mcap_path}")
        return out


def belief(posterior: ClassPosterior | None) -> str:
    """The table's "human (belief)" cell: the most probable class and its probability, or ``""``.

    A flat posterior names no class, ``(flat) p=0.13``: its top one at 0.13 among 8 classes read as a belief. Flat is
    under twice the uniform 1/K, and under an even chance (with 2 classes the top one always has one).
    """
    if posterior is None:
        return ""
    p = float(np.max(posterior.posterior))
    return f"{recognised_class(posterior.class_names, posterior.posterior) or '(flat)'} p={p:.2f}"


def posterior_for(plan: Plan, posteriors: dict[int, ClassPosterior]) -> ClassPosterior | None:
    """The belief a plan was made with.

    Lock-step: the posterior of the tick before the plan's (the occupancy it planned against); real time: the
    newest posterior stamped before the plan.
    """
    if plan.tick >= 0:
        earlier = [t for t, p in posteriors.items() if p.tick < plan.tick]
        return posteriors[max(earlier, key=lambda t: posteriors[t].tick)] if earlier else None
    before = [p for p in posteriors.values() if p.stamp <= plan.stamp]
    return max(before, key=lambda p: p.stamp) if before else None


def final_label(final: OccupancyGrid | None) -> str:
    """What a run's interference is scored against: ``final prediction``, or the final grid of another method."""
    return "final prediction" if final is None or final.method == "prediction" else f"final {final.method} occupancy"


def summarise(plans: list[Plan], states: list[RobotState], final_occupancy: OccupancyGrid | None,
              posteriors: dict[int, ClassPosterior], robot: Any, human_class: str, mcap_path: str | None,
              goal_tolerance: float = 0.02, t0: float | None = None, received: Sequence[float] | None = None
              ) -> Summary:
    """Summarise a run from its messages.

    Args:
        plans: Plans in arrival order (one per step; duplicates of a tick: the last wins).
        states: Executed robot states.
        final_occupancy: The last occupancy prediction (None: interference cost 0, not scored).
        posteriors: ClassPosterior by tick.
        robot: Robot model (sphere centres) for the interference cost.
        human_class: The true class of the observed demonstration.
        mcap_path: The run's log.
        goal_tolerance: Joint-space tolerance of "goal reached".
        t0: Start of the run on the messages' clock (default: 0 in lock-step, the first robot state in
            real time); the ``t_s`` of each step and ``reached_t_s`` count from it.
        received: Real time: when each plan of ``plans`` arrived (s, wall clock; the executor's log time): the
            steps are then the plans the executor adopted.
    """
    by_tick: dict[int, Plan] = {}
    for p in plans:
        by_tick[p.tick if p.tick >= 0 else len(by_tick)] = p
    keys = sorted(by_tick)
    ordered = [by_tick[t] for t in keys]
    states = sorted(states, key=lambda s: s.stamp)
    realtime = bool(ordered) and all(p.tick < 0 for p in ordered)
    if realtime and states:  # the plans the executor adopted (services.adopted_plans); without their arrival times,
        # those stamped before the run's last state (one made from it or later was never executed)
        keep = (adopted(list(received), [s.stamp for s in states]) if received is not None else
                [p.stamp < states[-1].stamp for p in ordered])
        keys = [k for k, a in zip(keys, keep, strict=True) if a]
        ordered = [p for p, a in zip(ordered, keep, strict=True) if a]
    if t0 is None:
        t0 = (states[0].stamp if states else ordered[0].stamp) if realtime else 0.0
    steps = [step_entry(p, t0, k) for k, p in zip(keys, ordered, strict=True)]  # ticks, or the plans' order
    for entry, plan in zip(steps, ordered, strict=True):
        entry["belief"] = belief(posterior_for(plan, posteriors))
    chosen = [s["chosen"] for s in steps]
    switch = None
    for i in range(1, len(chosen)):
        if chosen[i] != chosen[i - 1]:
            switch = steps[i]["step"]
    q = np.array([s.q for s in states]) if states else np.zeros((0, 0))
    stamps = np.array([s.stamp for s in states])
    cost = interference(robot, q, stamps, final_occupancy) if final_occupancy is not None and len(q) else 0.0
    # the goal it ended going for, since it last turned to it (a robot that reached one cup and then turned to the
    # other, or went back to the first later, has not reached it: it said so for the first time it got there)
    start = len(states)
    while start > 0 and states[start - 1].goal == states[-1].goal:
        start -= 1
    reached_states = [s for s in states[start:] if s.reached]
    left = None
    earlier = next((i for i in range(start) if states[i].reached), None) if not reached_states else None
    if earlier is not None:  # a goal reached and left: said, the run's goal is not
        gone = next(j for j in range(earlier, len(states)) if not states[j].reached or states[j].goal != states[
            earlier].goal)
        left = {"goal": states[earlier].goal, "reached_t_s": float(states[earlier].stamp - t0),
                "left_t_s": float(states[gone].stamp - t0)}
    reached_step = reached_t = None
    if reached_states:
        first = reached_states[0]
        reached_t = float(first.stamp - t0)
        if first.tick >= 0:  # lock-step: the step during which it was reached
            reached_step = first.tick
        else:  # real time: the step whose plan was the newest when it was reached
            before = [s for s in steps if s["t_s"] < reached_t]  # one made from the reached state came after it
            reached_step = before[-1]["step"] if before else None
    guarded = [i for i in range(1, len(states)) if is_separation_hold(states[i].reason)]
    separation_held = float(sum(states[i].stamp - states[i - 1].stamp for i in guarded))
    recognised, recognised_p, recognised_index, flat = None, None, None, False
    if posteriors:
        last = posteriors[max(posteriors)]
        best = int(np.argmax(last.posterior))
        recognised, recognised_p, recognised_index = last.class_names[best], float(last.posterior[best]), last.index
        flat = not recognised_class(last.class_names, last.posterior)
    goal_names = list(ordered[-1].goal_names) if ordered else []
    if left is not None and 0 <= left["goal"] < len(goal_names):
        left["goal"] = goal_names[left["goal"]]
    return Summary(steps=steps, chosen_goal_per_step=chosen, switch_step=switch, interference_cost=cost,
                   mcap_path=mcap_path, reached=bool(reached_states), reached_step=reached_step,
                   human_class=human_class, recognised_class=recognised, goal_names=goal_names,
                   reached_t_s=reached_t, scored_against=final_label(final_occupancy), recognised_p=recognised_p,
                   recognised_flat=flat, recognised_index=recognised_index, separation_held_s=separation_held,
                   left_goal=left, separation_at_end=bool(states) and is_separation_hold(states[-1].reason),
                   unit="plan" if realtime else "step", scored=final_occupancy is not None)
