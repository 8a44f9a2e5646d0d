"""``foresight demo --prepare DIR``: the demo's scenario as files, for running its services by hand or in containers.

The same inputs ``foresight demo`` makes before it starts the services -- the human's demonstration
(``DIR/human.npz``) and the prediction model trained without it (cached under ``--models-dir``) -- and one
config file, ``DIR/foresight.toml``, with each service's section holding exactly the options the demo passes
it on its command line (:func:`services.demo_services.service_options`), so that services started with
``--config DIR/foresight.toml`` (or ``FORESIGHT_CONFIG``) run the demo's scenario and print the same step
table. compose.yaml runs it as its one-shot ``prepare`` service. Zenoh options are left out: each deployment
says where its router is.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import tomli_w

from services.demo_services import extra_services, service_options, services_in_order
from shared.arguments import ArgumentParser
from shared.config import add_config_arguments, resolve_config
from shared.config_names import section_class
from shared.config_tree import config_options
from shared.runtime import interruptible
from shared.scene import load_scene

if TYPE_CHECKING:
    from services.demo import DemoConfig

__all__ = ["prepare", "prepare_or_stop", "config_tables"]

CONFIG_NAME = "foresight.toml"


def _value(config: Any, attrs: tuple[str, ...]) -> Any:
    for a in attrs:
        config = getattr(config, a)
    return config


def config_tables(options: dict[str, list[str]]) -> dict[str, dict[str, Any]]:
    """Each section's flags as its TOML table: the options whose value differs from the default.

    Args:
        options: Section -> its command-line flags (no Zenoh ones), parsed as the service parses them.

    Raises:
        ConfigError: A flag the section does not have or a bad value (as the service would say).
    """
    out: dict[str, dict[str, Any]] = {}
    for section, flags in options.items():
        cls = section_class(section)
        parser = ArgumentParser(prog=f"foresight {section}")
        add_config_arguments(parser, section, cls, with_zenoh=False)
        cfg, _ = resolve_config(section, cls, parser.parse_args(flags), env={}, with_zenoh=False)
        default = cls()
        table: dict[str, Any] = {}
        for option in config_options(section, cls):
            value = _value(cfg, option.attrs)
            if value == _value(default, option.attrs) or value is None:
                continue
            node = table
            for part in option.table[1:]:
                node = node.setdefault(part, {})
            node[option.field] = str(value) if isinstance(value, Path) else value
        out[section] = table
    return out


def prepare(cfg: DemoConfig, directory: Path, out: Callable[[str], None] = print) -> Path:
    """Write the scenario's inputs and ``directory/foresight.toml``; returns the config file's path."""
    from services.demo_run import prepare_inputs  # torch and the trainer (seconds): imported once a signal can cut it

    scene = load_scene(cfg.scene or None)
    scenario, model, human = prepare_inputs(cfg, scene, Path(directory), out)
    options = service_options(cfg, model, human, scenario.samples_per_tick, mcap=None)
    # compose.yaml's optional live view (profile live) reads the scene from "view"
    names = [*services_in_order(cfg), *extra_services(cfg), "view"]
    tables = config_tables({name: options[name] for name in names})
    path = Path(directory) / CONFIG_NAME
    header = (f"# Written by `foresight demo --prepare {directory}`: the demo's scenario ({scenario.demo.class_name} "
              f"#{scenario.demo.index}, {cfg.mode}),\n# one section per service; run each with --config {path} and "
              "its Zenoh options.\n\n")
    tmp = path.with_suffix(".tmp")
    tmp.write_text(header + tomli_w.dumps(tables))
    tmp.replace(path)  # never a half-written file for a service to read
    out(f"foresight demo: services' config {path}; run each of {', '.join(names)} as "
        f"`foresight SERVICE --config {path} --connect tcp/ROUTER:7447` (the executor last, or with its wait_for)")
    return path


def prepare_or_stop(cfg: DemoConfig, directory: Path, stop: threading.Event, out: Callable[[str], None] = print
                    ) -> int:
    """:func:`prepare`, cut short by SIGINT/SIGTERM; returns 0, or 130 when a signal stopped it (said in one line).

    The signal takes effect at once, while training too: compose's ``prepare`` ignored it, and ``docker compose down``
    waited out its 20 s grace and then killed it. A model cut short is not cached (written whole or not at all), and
    the config file, written last and whole, is not written: the services that wait for ``prepare`` do not start.
    """
    done = False
    try:
        with interruptible(stop):
            if not stop.is_set():  # a signal before this point (the demo's imports) stops it before any work
                prepare(cfg, directory, out)
                done = True
    except KeyboardInterrupt:
        pass
    if done:  # a signal after the work is done leaves it done
        return 0
    out(f"foresight demo: interrupted while preparing {directory}: its config file was not written and a model cut "
        "short is not cached; run it again to prepare it")
    return 130
