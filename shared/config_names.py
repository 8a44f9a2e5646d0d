"""Every configuration name that exists: sections, their options' variables; a misspelt one is an error.

A TOML file is shared by every service (one table per section) and the environment by every process
a command starts, so a name that matches nothing (``[zenho]``, ``[replayr]``,
``FORESIGHT_REPLAYER_RATEHZ``) would otherwise be ignored without a word. :func:`check_file_sections`
and :func:`check_environment` make it a :class:`~shared.config_tree.ConfigError` naming the closest
valid name, like an unknown key in a table.

:data:`SECTIONS` maps each section to its config dataclass (imported only when its names are needed);
:data:`OTHER_VARIABLES` lists the ``FORESIGHT_*`` variables that are not options of a section.
Variables starting with ``FORESIGHT_TEST_`` belong to the test suite and are not checked.
"""

from __future__ import annotations

import difflib
import importlib
import typing
from collections.abc import Iterable

from shared.config_tree import ENV_PREFIX, ConfigError, config_options

__all__ = ["SECTIONS", "OTHER_VARIABLES", "section_class", "check_file_sections", "check_environment",
           "closest", "check_services", "every_variable"]

SECTIONS: dict[str, str] = {
    "zenoh": "shared.config:ZenohConfig",
    "replayer": "services.replayer.core:ReplayerConfig",
    "tracker": "services.tracker.config:TrackerServiceConfig",
    "predictor": "services.predictor.core:PredictorConfig",
    "planner": "services.planner.config:PlannerServiceConfig",
    "executor": "services.executor.config:ExecutorConfig",
    "router": "tools.router:RouterConfig",
    "ros2": "services.ros2.service:Ros2ServiceConfig",
    "simrobot": "services.ros2.robot_sim:RobotSimConfig",
    "view": "services.view.config:ViewConfig",
    "demo": "services.demo:DemoConfig",
}
"""Section (TOML table, variable and command name) -> ``module:Class`` of its config dataclass."""

OTHER_VARIABLES: dict[str, str] = {
    f"{ENV_PREFIX}_CONFIG": "the TOML config file",
    f"{ENV_PREFIX}_BLAS_THREADS": "BLAS threads per process (shared.native_threads)",
    f"{ENV_PREFIX}_PARENT_PID": "set by foresight demo for its services (shared.runtime.watch_parent)",
    f"{ENV_PREFIX}_RUN_AS": "the image's entrypoint: UID:GID to run the command as (default: the owner of runs/)",
    f"{ENV_PREFIX}_RUNS_DIR": "the image's entrypoint: the directory whose owner runs the command (default /app/runs)",
    f"{ENV_PREFIX}_BASE_IMAGE": "compose.yaml / tools/compose_check.sh: the image's base (default python:3.11-slim)",
    f"{ENV_PREFIX}_WHEELHOUSE": "compose.yaml: an image whose root holds wheels the build prefers (docs/docker.md)",
    f"{ENV_PREFIX}_WHEELHOUSE_DIR": "tools/compose_check.sh: a directory of wheels the build prefers",
    f"{ENV_PREFIX}_SECURITY_DIR": "compose.secure.yaml: the directory of `foresight security init` (default "
                                  "./security)",
    f"{ENV_PREFIX}_CA_BUNDLE": "tools/compose_check.sh: extra CA certificates the build trusts (a proxy's)",
    f"{ENV_PREFIX}_ROUTER_ADDR": "compose.yaml: the host address the router's port 7447 is published on (default "
                                 "127.0.0.1; another machine's cell: the host's own address, docs/security.md)",
}
"""``FORESIGHT_*`` variables that are not options of a section, with what each is."""

TEST_PREFIX = f"{ENV_PREFIX}_TEST_"


def section_class(section: str) -> type:
    """The config dataclass of ``section`` (imports its module)."""
    module, _, name = SECTIONS[section].partition(":")
    return typing.cast(type, getattr(importlib.import_module(module), name))


def closest(name: str, valid: Iterable[str], prefix: str = "") -> str:
    """``"; did you mean X?"`` for the valid name closest to ``name``, or ``""`` when none is close.

    ``prefix``, shared by ``name`` and the names compared, is left out of the comparison: ``FORESIGHT_FOO`` is not
    close to ``FORESIGHT_CONFIG`` for their common ``FORESIGHT_``.
    """
    rest = name[len(prefix):] if name.startswith(prefix) else name
    names = {v[len(prefix):]: v for v in valid if v.startswith(prefix)}
    match = difflib.get_close_matches(rest, list(names), n=1, cutoff=0.6)
    return f"; did you mean {names[match[0]]}?" if match else ""


def check_services(names: Iterable[str], option: str, allowed: Iterable[str]) -> None:
    """Raise ConfigError naming ``option`` for a name in ``names`` that is none of the services ``allowed``.

    A service a command waits for or stops with, misspelt (``--stop-with exector``), is never seen: the command
    would wait, or run on, without a word.
    """
    allowed = list(allowed)
    for peer in names:
        if peer not in allowed:
            close = difflib.get_close_matches(peer, allowed, n=1)
            raise ConfigError(f"{option}: unknown service {peer!r}"
                              + (f" (did you mean {close[0]!r}?)" if close else f" (one of {', '.join(allowed)})"))


def every_variable() -> list[str]:
    """The variable of every option of every section of :data:`SECTIONS` (imports every config module)."""
    return [o.env for section in SECTIONS for o in config_options(section, section_class(section))]


def check_file_sections(data: dict[str, typing.Any], path: str = "config file") -> None:
    """Raise ConfigError for a top-level table of a config file that is no section.

    Args:
        data: The parsed TOML file.
        path: How to name the file in the message.
    """
    for key in data:
        if key not in SECTIONS:
            raise ConfigError(f"{path}: unknown section [{key}]{closest(key, SECTIONS)} "
                              f"(sections: {', '.join(SECTIONS)})")


def _likely_section(variable: str, sections: Iterable[str]) -> str | None:
    """The section closest to the start of a ``FORESIGHT_...`` variable that names none (``REPLAYR_RATE_HZ``: replayer).

    Each run of its first words is compared with the section names; the closest match wins, None when none is close.
    """
    words = variable[len(ENV_PREFIX) + 1:].lower().split("_")
    best, score = None, 0.0
    for k in range(1, len(words)):
        head = "_".join(words[:k])
        for name in sections:
            ratio = difflib.SequenceMatcher(None, head, name).ratio()
            if ratio >= 0.6 and ratio > score:
                best, score = name, ratio
    return best


def _section_of(variable: str, sections: Iterable[str]) -> str | None:
    """The section a ``FORESIGHT_<SECTION>_...`` variable addresses (the longest that fits), or None."""
    fits = [s for s in sections if variable.startswith(f"{ENV_PREFIX}_{s.upper()}_")]
    return max(fits, key=len) if fits else None


def check_environment(env: typing.Mapping[str, str], checked: typing.Mapping[str, type]) -> None:
    """Raise ConfigError for a ``FORESIGHT_*`` variable that matches no option, or one written in lower case.

    Variables of the ``checked`` sections must name one of their options; those of another section of
    :data:`SECTIONS` are left to the command that reads it; any other ``FORESIGHT_*`` variable must be
    one of :data:`OTHER_VARIABLES`.

    Args:
        env: The environment, e.g. ``os.environ``.
        checked: The sections the calling command reads, with their config dataclasses.
    """
    every_section = {*SECTIONS, *checked}
    known: dict[str, set[str]] = {}
    for variable in sorted(env):
        if variable.upper().startswith(f"{ENV_PREFIX}_") and not variable.startswith(f"{ENV_PREFIX}_"):
            raise ConfigError(f"environment: {variable} is read as nothing: Foresight's variables are upper case "
                              f"({variable.upper()})")
        if not variable.startswith(f"{ENV_PREFIX}_") or variable in OTHER_VARIABLES \
                or variable.startswith(TEST_PREFIX):
            continue
        section = _section_of(variable, every_section)
        if section is None:
            # the options of the section it most likely meant (every section's: every config module imported, torch
            # with the planner's, 8 s for one line), those of the checked ones, and the other variables
            meant = _likely_section(variable, SECTIONS)
            every = [*OTHER_VARIABLES, *([o.env for o in config_options(meant, section_class(meant))] if meant else []),
                     *(o.env for s, c in checked.items() for o in config_options(s, c))]
            raise ConfigError(f"environment: {variable} is no Foresight option"
                              f"{closest(variable, every, f'{ENV_PREFIX}_')} (options "
                              f"are FORESIGHT_<SECTION>_<OPTION>, sections: {', '.join(sorted(every_section))})")
        if section not in checked:
            continue
        if section not in known:
            known[section] = {o.env for o in config_options(section, checked[section])}
        if variable not in known[section]:
            where = "" if section == "zenoh" else f" (see foresight {section} --help)"
            raise ConfigError(f"environment: {variable} is no option of [{section}]"
                              f"{closest(variable, known[section], f'{ENV_PREFIX}_{section.upper()}_')}{where}")
