"""Configuration: one small dataclass per component, loaded file < environment < command line.

Every service holds one config dataclass of its own plus the common :class:`ZenohConfig`.
Values are resolved in this order, later wins:

1. the dataclass defaults (the embedded defaults: ``make demo`` needs nothing else);
2. a TOML file (``--config FILE`` or ``FORESIGHT_CONFIG``), with a ``[zenoh]`` table and one
   table per section, e.g. ``[replayer]``;
3. environment variables ``FORESIGHT_<SECTION>_<FIELD>``, e.g. ``FORESIGHT_REPLAYER_RATE_HZ=10``
   or ``FORESIGHT_ZENOH_CONNECT=tcp/127.0.0.1:7447``;
4. command-line flags ``--<field-name>``, e.g. ``--rate-hz 10``.

Field help texts, types and choices come from the dataclass, so ``--help`` shows every option.
A bad value raises :class:`ConfigError` with a one-line message naming the option.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import tomllib
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

__all__ = [
    "ConfigError",
    "ZenohConfig",
    "opt",
    "add_config_arguments",
    "resolve_config",
    "load_toml",
    "parse_value",
]

T = TypeVar("T")

ENV_PREFIX = "FORESIGHT"


class ConfigError(ValueError):
    """A configuration value is missing, malformed or out of range; the message names it."""


def opt(default: Any = dataclasses.MISSING, *, help: str, choices: Sequence[Any] | None = None,
        default_factory: Any = dataclasses.MISSING) -> Any:
    """Declare a config field with its help text (and optional choices).

    Args:
        default: Default value (immutable).
        help: One-line help shown by ``--help``.
        choices: Allowed values, checked on load.
        default_factory: Factory for mutable defaults (lists).

    Returns:
        A ``dataclasses.field``.
    """
    meta = {"help": help, "choices": tuple(choices) if choices is not None else None}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@dataclasses.dataclass
class ZenohConfig:
    """The Zenoh section shared by every service (``[zenoh]`` in the TOML file)."""

    mode: str = opt("peer", help="Zenoh session mode", choices=("peer", "client", "router"))
    listen: list[str] = opt(default_factory=lambda: ["tcp/127.0.0.1:0"],
                            help="endpoints to listen on (comma-separated); tcp/127.0.0.1:0 picks a free port")
    connect: list[str] = opt(default_factory=lambda: ["tcp/127.0.0.1:7447"],
                             help="endpoints to connect to (comma-separated), e.g. the router's")
    multicast_scouting: bool = opt(False, help="enable multicast scouting (off: it leaves the machine)")
    prefix: str = opt("foresight", help="key-expression prefix of every Foresight key")
    connect_timeout_s: float = opt(60.0, help="client mode: keep retrying to reach the router this long (s, "
                                   "bounded back-off, logged) before giving up; 0 = fail at once")

    def validate(self) -> None:
        """Check endpoint syntax, the prefix and the connect timeout."""
        if not (self.connect_timeout_s >= 0 and math.isfinite(self.connect_timeout_s)):
            raise ConfigError(f"zenoh.connect_timeout_s: must be >= 0, got {self.connect_timeout_s}")
        for name in ("listen", "connect"):
            for ep in getattr(self, name):
                if "/" not in ep or not ep.split("/", 1)[1]:
                    raise ConfigError(f"zenoh.{name}: endpoint {ep!r} is not of the form proto/address")
        if not self.prefix or self.prefix.startswith("/") or self.prefix.endswith("/") or "*" in self.prefix:
            raise ConfigError(f"zenoh.prefix: {self.prefix!r} must be a non-empty key without wildcards "
                              "or leading/trailing '/'")


# ----------------------------------------------------------------------------------------------
# value parsing


def _base_type(tp: Any) -> tuple[Any, bool]:
    """Return (inner type, is_list) for a field annotation (``X``, ``list[X]``, ``X | None``)."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return _base_type(args[0])
    if origin is list:
        return typing.get_args(tp)[0], True
    return tp, False


def parse_value(name: str, tp: Any, raw: Any, choices: Sequence[Any] | None = None) -> Any:
    """Convert ``raw`` (a string from env/CLI, or a TOML value) to the field type ``tp``.

    Args:
        name: Dotted option name used in error messages, e.g. ``replayer.rate_hz``.
        tp: The field's annotation (resolved).
        raw: The value to convert.
        choices: Allowed values, if any.

    Returns:
        The converted value.

    Raises:
        ConfigError: If the value cannot be converted or is not among ``choices``.
    """
    inner, is_list = _base_type(tp)
    if is_list:
        if isinstance(raw, str):
            items = [s.strip() for s in raw.split(",") if s.strip()]
        elif isinstance(raw, list | tuple):
            items = list(raw)
        else:
            raise ConfigError(f"{name}: expected a list, got {raw!r}")
        return [parse_value(name, inner, item, choices) for item in items]
    value: Any
    try:
        if inner is bool:
            if isinstance(raw, bool):
                value = raw
            elif isinstance(raw, str) and raw.strip().lower() in ("1", "true", "yes", "on"):
                value = True
            elif isinstance(raw, str) and raw.strip().lower() in ("0", "false", "no", "off"):
                value = False
            else:
                raise ValueError
        elif inner is int:
            if isinstance(raw, bool) or (isinstance(raw, float) and not raw.is_integer()):
                raise ValueError
            value = int(raw)
        elif inner is float:
            if isinstance(raw, bool):
                raise ValueError
            value = float(raw)
            if value != value or value in (float("inf"), float("-inf")):
                raise ValueError
        elif inner is Path:
            value = Path(str(raw)).expanduser()
        elif inner is str:
            if not isinstance(raw, str):
                raise ValueError
            value = raw
        else:  # pragma: no cover - config dataclasses only use the types above
            raise ConfigError(f"{name}: unsupported option type {inner!r}")
    except (TypeError, ValueError):
        kind = getattr(inner, "__name__", str(inner))
        raise ConfigError(f"{name}: expected {kind}, got {raw!r}") from None
    if choices is not None and value not in choices:
        raise ConfigError(f"{name}: {value!r} is not one of {', '.join(map(str, choices))}")
    return value


# ----------------------------------------------------------------------------------------------
# file / env / CLI


def load_toml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a TOML config file.

    Raises:
        ConfigError: If the file is missing or not valid TOML.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"config file {str(p)!r} not found")
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {str(p)!r}: {exc}") from None


def _fields(cls: type) -> list[tuple[dataclasses.Field[Any], Any]]:
    hints = typing.get_type_hints(cls)
    return [(f, hints[f.name]) for f in dataclasses.fields(cls)]


ZENOH_FLAG_NAMES = {"mode": "zenoh_mode"}
"""Zenoh options whose flag differs from the field name in every command (``--mode`` is the services' own)."""


def _flag(field_name: str) -> str:
    return "--" + field_name.replace("_", "-")


def add_config_arguments(parser: argparse.ArgumentParser, section: str, cls: type,
                         with_zenoh: bool = True) -> None:
    """Add ``--config``, the Zenoh flags and one flag per field of ``cls`` to ``parser``.

    Flags default to ``None`` (argparse.SUPPRESS) so that only given flags override file and env.
    The Zenoh session mode is always ``--zenoh-mode``; any other Zenoh field whose flag a section
    field already uses is offered as ``--zenoh-<name>`` instead.
    """
    if not any(a.dest == "config" for a in parser._actions):
        parser.add_argument("--config", metavar="FILE", default=None,
                            help=f"TOML config file (or ${ENV_PREFIX}_CONFIG)")
    groups: list[tuple[str, type]] = [(section, cls)]
    if with_zenoh:
        groups.append(("zenoh", ZenohConfig))
    for sec, kls in groups:
        group = parser.add_argument_group(f"[{sec}] options (env {ENV_PREFIX}_{sec.upper()}_<NAME>)")
        defaults = kls()
        for f, tp in _fields(kls):
            inner, is_list = _base_type(tp)
            default = getattr(defaults, f.name)
            shown = ",".join(map(str, default)) if is_list else default
            text = f"{f.metadata.get('help', '')} (default: {shown})"
            dest = f"{sec}__{f.name}"
            flag = _flag(ZENOH_FLAG_NAMES.get(f.name, f.name) if sec == "zenoh" else f.name)
            if flag in parser._option_string_actions:
                # a section field of the same name (e.g. the replayer's --mode) keeps the short flag
                flag = _flag(f"{sec}_{f.name}")
            if inner is bool and not is_list:
                group.add_argument(flag, dest=dest,
                                   action=argparse.BooleanOptionalAction, default=argparse.SUPPRESS, help=text)
            else:
                choices = f.metadata.get("choices")
                metavar = "{" + ",".join(map(str, choices)) + "}" if choices else f.name.upper()
                group.add_argument(flag, dest=dest, metavar=metavar,
                                   default=argparse.SUPPRESS, help=text)


def _resolve_section(section: str, cls: type[T], file_values: dict[str, Any],
                     env: typing.Mapping[str, str], cli: dict[str, Any], base: T | None = None,
                     cli_names: dict[str, str] | None = None) -> T:
    cli_names = cli_names or {}
    unknown = set(file_values) - {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    if unknown:
        raise ConfigError(f"[{section}]: unknown option(s) {', '.join(sorted(unknown))}")
    kwargs: dict[str, Any] = {}
    for f, tp in _fields(cls):
        name = f"{section}.{f.name}"
        choices = f.metadata.get("choices")
        env_key = f"{ENV_PREFIX}_{section.upper()}_{f.name.upper()}"
        if f"{section}__{f.name}" in cli:
            kwargs[f.name] = parse_value(cli_names.get(f.name, _flag(f.name)), tp, cli[f"{section}__{f.name}"],
                                         choices)
        elif env_key in env:
            kwargs[f.name] = parse_value(env_key, tp, env[env_key], choices)
        elif f.name in file_values:
            kwargs[f.name] = parse_value(name, tp, file_values[f.name], choices)
    obj = dataclasses.replace(base, **kwargs) if base is not None else cls(**kwargs)  # type: ignore[type-var]
    validate = getattr(obj, "validate", None)
    if callable(validate):
        validate()
    return obj


def resolve_config(section: str, cls: type[T], args: argparse.Namespace | None = None,
                   env: typing.Mapping[str, str] | None = None,
                   config_file: str | os.PathLike[str] | None = None,
                   with_zenoh: bool = True, zenoh_base: ZenohConfig | None = None) -> tuple[T, ZenohConfig]:
    """Resolve a section's config and the Zenoh config from defaults, file, env and CLI.

    Args:
        section: Section name, e.g. ``"replayer"``.
        cls: The section's dataclass.
        args: Parsed CLI namespace from a parser set up by :func:`add_config_arguments`.
        env: Environment mapping (default ``os.environ``).
        config_file: TOML file; overrides ``args.config`` and ``$FORESIGHT_CONFIG``.
        with_zenoh: Also resolve the ``[zenoh]`` section.
        zenoh_base: Defaults of the Zenoh section for this command (e.g. the router's listen endpoint).

    Returns:
        ``(section_config, zenoh_config)``.

    Raises:
        ConfigError: On any bad value, unknown option or unreadable file.
    """
    env = os.environ if env is None else env
    cli = dict(vars(args)) if args is not None else {}
    path = config_file or cli.get("config") or env.get(f"{ENV_PREFIX}_CONFIG")
    data = load_toml(path) if path else {}
    for key, value in data.items():
        if not isinstance(value, dict):
            raise ConfigError(f"config file: top-level key {key!r} must be a table like [{key}]")
    sec = _resolve_section(section, cls, data.get(section, {}), env, cli)
    shadowed = {f.name for f in dataclasses.fields(ZenohConfig)} & {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    names = {n: _flag(f"zenoh_{n}" if n in shadowed else ZENOH_FLAG_NAMES.get(n, n))
             for n in (f.name for f in dataclasses.fields(ZenohConfig))}
    zen = (_resolve_section("zenoh", ZenohConfig, data.get("zenoh", {}), env, cli, zenoh_base, names)
           if with_zenoh else ZenohConfig())
    return sec, zen
