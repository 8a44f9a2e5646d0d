"""The demo's inputs, checked before anything heavy is imported: a misspelt class, scene or library is said at once.

``foresight demo --human-class nonsense`` (or ``--scene``, ``--library``) said so after 8-10 s, the time the demo
took to import the planner, the predictor and matplotlib (a newcomer's review). These checks need the scene, the
library's class names and, for a library file, the library: a second at most.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import MISSING
from pathlib import Path
from typing import TYPE_CHECKING

from services.demo_services import demo_set_options
from shared.config import ConfigError, load_toml, resolve_config
from shared.config_names import SECTIONS, closest, section_class
from shared.config_tree import ENV_PREFIX, config_options, file_value
from shared.feature_sets import LIVE_MAPPING, require_mapping
from shared.library import MotionLibrary, load_library
from shared.runtime import UserError
from shared.scene import Scene, load_scene

if TYPE_CHECKING:
    from services.demo import DemoConfig

__all__ = ["DEFAULT_HUMAN_CLASS", "human_label", "library_for", "check_goals", "check_inputs", "share_config_file"]

DEFAULT_HUMAN_CLASS = "red_cup"
"""The human reaches for the red cup (the paper's Fig. 8); the robot plans for both cups."""


def human_label(names: Sequence[str], human_class: str, source: str) -> int:
    """The label of ``human_class`` among a library's class ``names`` (by name or index; ``""``: the default).

    ``""`` is :data:`DEFAULT_HUMAN_CLASS` if the library has it, else the last class.

    Raises:
        UserError: Unknown class, with the library's classes and the closest name.
    """
    names = list(names)
    if not human_class:
        return names.index(DEFAULT_HUMAN_CLASS) if DEFAULT_HUMAN_CLASS in names else len(names) - 1
    if human_class in names:
        return names.index(human_class)
    if human_class.isdigit() and int(human_class) < len(names):
        return int(human_class)
    hint = ("; the paper's library: --human-class compound_1, the reach of its authors' Table I trials "
            "(docs/experiments.md)" if "compound_1" in names else "")  # the default, blue_cup, is the synthetic's
    raise UserError(f"--human-class {human_class!r}: not a class of {source} ({', '.join(names)})"
                    + (closest(human_class, names) or hint))


_loaded: dict[tuple[str, int], MotionLibrary] = {}
"""Library files loaded by this process, by path and modification time (the check, then each run of --compare)."""


def library_for(cfg: DemoConfig, scene: Scene) -> MotionLibrary:
    """The demo's motion library: ``cfg.library``, or the synthetic one for ``scene``'s cups (generated: 2 s)."""
    if cfg.library is None:
        from shared.synthetic import generate_library

        return generate_library(seed=0, scene=scene)  # its cup classes reach for this scene's cups
    path = Path(cfg.library)
    try:
        key = (str(path.resolve()), path.stat().st_mtime_ns)
    except OSError:
        key = None  # load_library names what is wrong with it
    lib = _loaded.get(key) if key else None
    if lib is None:
        lib = load_library(cfg.library)  # its warnings (demonstrations dropped) once, not at each check and run
        if key:
            _loaded[key] = lib
    require_mapping(lib.feature_names, "foresight demo (HumanPose messages, occupancy)",
                    f"library {lib.source}", exact=LIVE_MAPPING)
    return lib


def check_goals(cfg: DemoConfig, scene: Scene) -> None:
    """Raise ConfigError for a goal of ``cfg.goals`` that is not a cup of ``scene``."""
    cups = [c.name for c in scene.cups]
    goals = [g.strip() for g in cfg.goals.split(",") if g.strip()]
    unknown = [g for g in goals if g not in cups]
    if unknown:
        raise ConfigError(f"demo.goals: {', '.join(map(repr, unknown))} not a cup of scene {scene.name} "
                          f"(its cups: {', '.join(cups)})")
    if len(set(goals)) != len(goals):  # the planner refuses it, after the demo's start-up
        raise ConfigError(f"demo.goals: each cup once, got {','.join(goals)}")


def check_inputs(cfg: DemoConfig) -> None:
    """Raise the error the run would raise later for its scene, library or human class.

    Raises:
        ConfigError, SceneError, LibraryError, FeatureError, UserError: As the run would (one line each, by
            ``cli_errors``).
    """
    scene = load_scene(cfg.scene or None)
    check_goals(cfg, scene)
    if cfg.library is None:  # the synthetic library's classes are its layout's goals: no need to generate it
        from shared.synthetic import DEFAULT_CLASSES, load_layout

        layout = load_layout(None, scene)
        names, source = layout.goal_names[:DEFAULT_CLASSES], f"the synthetic library (layout {layout.name})"
    else:
        lib = library_for(cfg, scene)
        names, source = list(lib.class_names), str(lib.source)
    human_label(names, cfg.human_class, source)


_DEMO_ZENOH_FLAGS = {"prefix": "--prefix", "security_dir": "--security"}
"""The demo's options of the ``[zenoh]`` options it sets (its router's endpoints are its own)."""


def share_config_file(path: str | None, cfg: DemoConfig) -> None:
    """Give the services the demo's config file, every section of it checked now.

    ``--config FILE`` applied only its ``[demo]`` section (``FORESIGHT_CONFIG=FILE`` reached the services): the
    services, which read ``FORESIGHT_CONFIG``, get the same file, and each section the file and the environment set
    is resolved here, so that a misspelt option or a bad value is one error before anything starts. An option the
    demo sets on a service's command line (:func:`services.demo_services.demo_set_options`) is an error where the
    file or a variable sets it too: the flag would win, without a word.

    Raises:
        ConfigError: A section of the file or a variable of the environment that its command would refuse, or that
            sets what the demo sets.
    """
    if path:
        os.environ[f"{ENV_PREFIX}_CONFIG"] = str(Path(path).resolve())
    for section in SECTIONS:
        if section != "demo":
            resolve_config(section, section_class(section), with_zenoh=False)
    file = os.environ.get(f"{ENV_PREFIX}_CONFIG")
    data = load_toml(file) if file else {}
    own = {o.field: o.flag for o in config_options("demo", type(cfg))}  # a service's rate_hz: the demo's --rate-hz
    clashes = [f"{where} (the demo's {hint[o.field]})" if o.field in hint else where
               for section, options in demo_set_options(cfg).items() for o in options
               for hint in ((_DEMO_ZENOH_FLAGS if section == "zenoh" else own),)
               for where in ((f"{o.name} in {file}",) if file_value(data.get(section, {}), o) is not MISSING else ())
               + ((f"${o.env}",) if o.env in os.environ else ())]
    if clashes:
        raise ConfigError(f"{'; '.join(clashes)}: foresight demo sets this on its services' command lines, from its "
                          "own options (foresight demo --help), and a flag beats the file and the environment; set "
                          "it with the demo's option, or run the services alone (README: running one service)")
