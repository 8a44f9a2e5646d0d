"""The human side of an experiment: which class reaches which cup, and models that never saw the run.

* :func:`load_experiment_library` reads a library for a scene (``synthetic``: the embedded synthetic
  library generated for that scene's cups).
* :func:`cup_class` finds the class whose demonstrations reach for a cup: the class whose mean reach
  point (where the hand gets farthest from its start) lies nearest the cup, horizontally. The paper's
  recorded library was not made in these scenes, so the distance is reported with the choice.
* :class:`HeldOutModels` trains (and caches) prediction models without given demonstrations; with
  one model per held-out demonstration only that demonstration's class is refitted. Every instance
  with the same models directory shares one fit cache, kept in its ``fits/`` and shared with the other
  processes that use it (:func:`~services.experiments.fit_store.fit_store`): its entries are keyed by their
  data and options, so Table I, the switch, its mirror and the timing, in any of the report's worker
  processes, reuse each other's class fits and sweeps.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import MutableMapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from services.scenario import model_for
from shared.human import HumanModel, reach_points
from shared.library import Demonstration, MotionLibrary, load_library, save_library
from shared.runtime import UserError
from shared.scene import Scene

from .fit_store import fit_store

__all__ = ["SYNTHETIC", "FAR_FROM_CUP_M", "load_experiment_library", "library_tag", "short_name", "CupClass",
           "cup_class", "HeldOutModels", "human_file", "samples_per_tick", "class_at_cup", "human_class",
           "draw_demos", "table1_demos"]

FAR_FROM_CUP_M = 0.3
"""A class whose mean reach ends further than this from its cup (horizontally) does not reach for it: the synthetic
classes end 1-2 cm from theirs, the paper's library's nearest 0.13-0.46 m (docs/experiments.md)."""

SYNTHETIC = "synthetic"
"""Library name of the embedded synthetic library (generated for the experiment's scene)."""


def load_experiment_library(spec: str | Path, scene: Scene) -> MotionLibrary:
    """``"synthetic"`` (the synthetic library, seed 0, its cup goals at ``scene``'s cups) or a library path."""
    if str(spec) == SYNTHETIC:
        from shared.synthetic import generate_library

        return generate_library(seed=0, scene=scene)
    return load_library(spec)


def library_tag(spec: str) -> str:
    """A library spec's name in file names, report keys and progress lines: ``synthetic`` or its path's last part."""
    return SYNTHETIC if spec == SYNTHETIC else Path(spec).name


def short_name(source: str) -> str:
    """A library's name for titles: ``synthetic`` or the last part of its path."""
    return SYNTHETIC if source.startswith(SYNTHETIC) else Path(source.rstrip("/")).name


@dataclass(frozen=True)
class CupClass:
    """The class of a library that reaches for a cup.

    Attributes:
        cup: The cup's name.
        label: Class index; ``name`` its name.
        distance: Horizontal distance (m) from the class's mean reach point to the cup.
    """

    cup: str
    label: int
    name: str
    distance: float

    def warning(self) -> str:
        """A line when the class does not reach for its cup (its mean reach ends beyond :data:`FAR_FROM_CUP_M`)."""
        if not self.distance > FAR_FROM_CUP_M:
            return ""
        return (f"warning: class {self.name}'s mean reach ends {self.distance:.2f} m from {self.cup}, more than "
                f"{FAR_FROM_CUP_M:g}: this human does not reach for that cup, and the runs measure a person who is "
                "not where the cup is (--human-cup, or a library whose class reaches it)")

    def held_out(self, pool: int, demos: int) -> int:
        """``demos`` held-out demonstrations of the class's ``pool``, or a UserError when none would be left to train.

        Before, ``--demos`` above the pool held every demonstration out, and the model's training said only
        "no demonstrations for class(es)".
        """
        if demos >= pool:
            raise UserError(f"--demos {demos}: class {self.name} has {pool} demonstrations, and the held-out ones are "
                            f"left out of its model: at most {pool - 1}")
        return demos


def cup_class(library: MotionLibrary, scene: Scene, cup: str, exclude: tuple[int, ...] = ()) -> CupClass:
    """The class whose mean reach point is nearest ``cup`` of ``scene`` (horizontal distance).

    Args:
        library: The motion library.
        scene: The scene the demonstrations are placed in.
        cup: Cup name.
        exclude: Class labels not to choose (e.g. the class chosen for another cup).
    """
    human = HumanModel()
    best: CupClass | None = None
    for m in range(len(library.class_names)):
        if m in exclude or not library.by_class(m):
            continue
        c = class_at_cup(library, scene, cup, m, human)
        if best is None or c.distance < best.distance:
            best = c
    if best is None:
        raise UserError(f"library {library.source}: no class with demonstrations to reach {cup}")
    return best


def human_class(library: MotionLibrary, scene: Scene, trial: tuple[str, tuple[int, ...]] | None, cup: str
                ) -> CupClass:
    """The human's class of an experiment: the class of the authors' ``trial``, else the class nearest ``cup``.

    ``trial`` is a (class name, demonstrations) of ``protocol.authors_trial``; its class's cup is the nearest one.
    """
    if trial is not None:
        return class_at_cup(library, scene, None, library.class_names.index(trial[0]))
    return cup_class(library, scene, cup)


def class_at_cup(library: MotionLibrary, scene: Scene, cup: str | None, label: int,
                 human: HumanModel | None = None) -> CupClass:
    """Class ``label`` of ``library`` as the human's class for ``cup`` (None: the cup nearest its mean reach point).

    Returns:
        The class, its cup and the horizontal distance from its mean reach point to that cup.
    """
    if cup is not None:
        scene.cup(cup)  # an unknown cup: SceneError naming it
    demos = library.by_class(label)
    if not demos:
        raise UserError(f"library {library.source}: class {library.class_names[label]} has no demonstrations")
    reach, _ = reach_points(human or HumanModel(), [d.features for d in demos], scene)
    gaps = {c.name: float(np.linalg.norm(reach.mean(axis=0)[:2] - c.center[:2])) for c in scene.cups}
    cup = cup or min(gaps, key=gaps.__getitem__)
    return CupClass(cup, label, library.class_names[label], gaps[cup])


def draw_demos(pool: int, n: int, seed: int, draw: int = 0) -> list[int]:
    """The held-out demonstrations of a class of ``pool``: the first ``n`` of ``seed``'s draw of ``max(n, draw)``.

    A draw of 3 was not the first 3 of a draw of 5 (seed 0: [12, 15, 19] against [6, 7, 11, 14, 17]): the pace
    sweep at Table I's pace ran other demonstrations than Table I, and said no planner touched the human where
    Table I's basic STOMP did (on #6). Sorted indices into the pool, at most ``pool - 1`` drawn.
    """
    drawn = np.random.default_rng(seed).choice(pool, size=max(n, min(draw, pool - 1)), replace=False)
    return sorted(drawn[:n].tolist())


def table1_demos(pool: int, n: int, trial: tuple[str, tuple[int, ...]] | None, seed: int, draw: int = 0
                 ) -> tuple[list[int], str]:
    """Table I's ``n`` held-out demonstrations of a class of ``pool``, as indices into it, and how they were chosen.

    With the authors' ``trial`` (``protocol.authors_trial``): their motions, then the class's other demonstrations
    in order, as the switch takes them (``--demos 8`` ran the authors' 5 and said nothing); else
    :func:`draw_demos`. ``n`` is checked by :meth:`CupClass.held_out`.
    """
    if trial is None:
        return draw_demos(pool, n, seed, draw), f"drawn with seed {seed}"
    order = [i for i in trial[1] if i < pool] + [i for i in range(pool) if i not in trial[1]]
    return order[:n], "the authors' motions" + (", then the class's others" if n > len(trial[1]) else "")


def samples_per_tick(demo: Demonstration, steps: int) -> int:
    """Poses per step so that the demonstration spans ``steps`` replanning steps."""
    return max(1, math.ceil(demo.n_samples / steps))


def human_file(library: MotionLibrary, demo: Demonstration, directory: Path) -> Path:
    """A one-demonstration library file for the replayer (written once per demonstration).

    The name carries a digest of the demonstration's data and class: two libraries (the report runs
    them side by side in one work directory) never share a file for their own class ``label`` / ``index``.
    """
    tag = hashlib.sha256(np.ascontiguousarray(demo.features, dtype=np.float64).tobytes()
                         + f"{demo.class_name}|{demo.label}|{demo.index}".encode()).hexdigest()[:12]
    path = Path(directory) / f"human-{demo.label}-{demo.index}-{tag}.npz"
    if not path.is_file():  # save_library writes whole, then renames: report workers share the directory
        save_library(MotionLibrary(class_names=list(library.class_names), demos=[demo], issues=[],
                                   source=f"{library.source} ({demo.class_name} #{demo.index})"), path)
    return path


@dataclass
class HeldOutModels:
    """Prediction models trained without given demonstrations, cached in ``models_dir``.

    Attributes:
        library: The motion library.
        scene: The scene the swept volumes are placed in.
        models_dir: Cache directory.
        components: Gaussians per class (None: the trainer's default, 20 as in the paper).
        volume: Volume method (None: the trainer's default).
        fits: ``train_model``'s fit cache (None: the models directory's shared store, ``models_dir/fits``).
    """

    library: MotionLibrary
    scene: Scene
    models_dir: Path
    components: int | None = None
    volume: str | None = None
    fits: MutableMapping[str, Any] | None = field(default=None, repr=False)

    def without(self, demos: list[Demonstration]) -> Path:
        """The model file trained on every demonstration but ``demos``."""
        fits = self.fits if self.fits is not None else fit_store(Path(self.models_dir) / "fits")
        return model_for(self.library, self.scene, demos, self.models_dir, self.components, progress=False,
                         fit_cache=fits, volume=self.volume)
