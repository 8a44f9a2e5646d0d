"""Configuration: one dataclass per component, nested like the components, loaded file < environment < flags.

Every service holds one config dataclass of its own plus the common :class:`ZenohConfig`. A config
dataclass holds the configs of the components it builds as nested dataclass fields (declared with
:func:`nested`): the planner service's config holds the planner's (:class:`~services.planner.core.PlannerConfig`),
which holds STOMP's (``stomp``) and the costs' (``cost``). Every field of that tree has one name,
and values are resolved in this order, later wins:

1. the dataclass defaults (the embedded defaults: ``make demo`` needs nothing else);
2. a TOML file (``--config FILE`` or ``FORESIGHT_CONFIG``) with a ``[zenoh]`` table, one table per
   section, e.g. ``[replayer]``, and one sub-table per nested config, e.g. ``[planner.stomp]``;
3. environment variables ``FORESIGHT_<SECTION>[_<NESTED>...]_<FIELD>``, e.g.
   ``FORESIGHT_REPLAYER_RATE_HZ=10``, ``FORESIGHT_PLANNER_STOMP_ITERATIONS=20`` or
   ``FORESIGHT_ZENOH_CONNECT=tcp/127.0.0.1:7447``;
4. command-line flags: ``--<field-name>`` for the section's own fields (``--rate-hz 10``) and
   ``--<nested>.<field-name>`` for nested ones (``--stomp.iterations 20``, ``--cost.w-human 0``).

A nested config declared ``inline`` (the planner's inside the planner service's) shares its parent's
table, variables and flags: its fields read as the section's own (``[planner] device``,
``--device``), its own nested configs keep their names (``[planner.stomp]``, ``--stomp.iterations``).
Fields a parent sets itself (STOMP's device, dtype and seed are the planner's) are hidden with
``nested(..., hide=...)``.

Help texts, types and choices come from the dataclasses (``opt(help=...)``, else the class docstring's
``Attributes:`` entry, else the field's trailing comment), so ``--help`` shows every option, grouped
by table. A bad value raises :class:`ConfigError` with a one-line message naming the option.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import tomllib
import typing
from pathlib import Path
from typing import Any, Protocol, TypeVar

from shared.config_names import SECTIONS, check_environment, check_file_sections, closest
from shared.config_tree import (
    ENV_PREFIX,
    ConfigError,
    Option,
    base_type,
    config_options,
    config_tables,
    fields_of,
    file_value,
    is_config,
    nested,
    opt,
    parse_value,
)
from shared.data_files import relative_to_cwd
from shared.endpoints import HOST_PORT, check_host_port, endpoint_host_port, picked_port
from shared.security.acl import OBSERVER, ROLES

__all__ = [
    "ConfigError",
    "ZenohConfig",
    "endpoint_host_port",
    "opt",
    "nested",
    "Option",
    "config_options",
    "add_config_arguments",
    "resolve_config",
    "load_toml",
    "parse_value",
    "check_prefix",
    "LOG_LEVELS",
]

T = TypeVar("T")

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
"""The ``log_level`` choices of every section."""


def check_prefix(prefix: str, option: str) -> None:
    """Raise :class:`ConfigError` naming ``option`` unless ``prefix`` is a key Zenoh takes under the run's keys.

    Non-empty ``/``-separated chunks without the wildcard and special characters ``*``, ``$``, ``#`` and ``?``
    (else Zenoh refuses it with a ``ZError`` when a session first declares a key under it).
    """
    bad = sorted(set(prefix) & set("*$#?"))
    if not prefix or "" in prefix.split("/") or bad:
        raise ConfigError(f"{option}: {prefix!r} must be a Zenoh key: non-empty '/'-separated chunks without '*', "
                          "'$', '#' or '?'" + (f" (it has {' '.join(bad)})" if bad else ""))
    if any(c.isspace() or not c.isprintable() for c in prefix):  # "foresight " would be a key space of its own
        raise ConfigError(f"{option}: {prefix!r} has a space or a control character; a prefix differing by one "
                          "from the other services' would never meet them")


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
    require_connection: bool = opt(False, help="any mode: give up (one line, exit status 2) when no router or peer "
                                   "answered within connect_timeout_s; default: log it within seconds and keep "
                                   "retrying")
    security_dir: str = opt("", help="mutual TLS and access control: the directory of `foresight security init` "
                            "(ca.crt, <role>.crt, <role>.key); tcp/ endpoints become tls/. Empty: plain TCP "
                            "(loopback only)")
    role: str = opt("", help=f"with security_dir: the certificate this session presents ({', '.join(ROLES)}); "
                    "empty: the command's own (a service its name, tools observer)")

    def validate(self) -> None:
        """Check endpoint syntax, the prefix and the connect timeout."""
        if not (self.connect_timeout_s >= 0 and math.isfinite(self.connect_timeout_s)):
            raise ConfigError(f"zenoh.connect_timeout_s: must be >= 0, got {self.connect_timeout_s}")
        for name in ("listen", "connect"):
            for ep in getattr(self, name):
                if "/" not in ep or not ep.split("/", 1)[1]:
                    raise ConfigError(f"zenoh.{name}: endpoint {ep!r} is not of the form proto/address")
                if ep.split("/", 1)[0] in HOST_PORT:  # tcp/127.0.0.1:abc was taken, and retried for ever
                    check_host_port(f"zenoh.{name}", ep, lowest=0 if name == "listen" else 1)
        if not self.connect and self.mode != "router" and not self.multicast_scouting:
            # an empty FORESIGHT_ZENOH_CONNECT ran a service nobody could find
            if self.mode == "client":  # a client listens on nothing: it reaches only what it connects to
                raise ConfigError("zenoh.connect: empty, and a client reaches only the endpoints it connects to "
                                  "(scouting off): it would reach nothing; give the router's endpoint, e.g. "
                                  "tcp/127.0.0.1:7447")
            if all(picked_port(ep) for ep in self.listen):
                raise ConfigError(f"zenoh.connect: empty, and this peer listens on no fixed port "
                                  f"({', '.join(self.listen) or 'nothing'}) with scouting off: nothing can reach it; "
                                  "give the router's endpoint, e.g. tcp/127.0.0.1:7447")
        if self.role and self.role not in ROLES:
            raise ConfigError(f"zenoh.role: {self.role!r} is no role{closest(self.role, ROLES)} "
                              f"(roles: {', '.join(ROLES)})")
        check_prefix(self.prefix, "zenoh.prefix")


# ----------------------------------------------------------------------------------------------
# file / env / CLI


def load_toml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a TOML config file.

    Raises:
        ConfigError: If the file is missing or not valid TOML.
    """
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"config file {str(p)!r} is a directory, not a TOML file")
    if not p.is_file():
        raise ConfigError(f"config file {str(p)!r} not found{relative_to_cwd(p)}")
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError) as exc:  # not TOML, not UTF-8, unreadable
        raise ConfigError(f"config file {str(p)!r}: {exc}") from None


ZENOH_FLAG_NAMES = {"mode": "zenoh_mode", "security_dir": "security"}
"""Zenoh options whose flag differs from the field name in every command (``--mode`` is the services' own)."""


class ArgumentGroup(Protocol):
    """What :func:`add_config_arguments` needs of an argparse group (``parser.add_argument_group(...)``)."""

    def add_argument(self, *names: str, **kwargs: Any) -> argparse.Action: ...


def _flag(field_name: str) -> str:
    return "--" + field_name.replace("_", "-")


def _zenoh_flags(section_flags: set[str]) -> dict[str, str]:
    """Flag of each Zenoh field: ``--zenoh-mode``, and ``--zenoh-<name>`` where a section field has the flag."""
    out = {}
    for f in dataclasses.fields(ZenohConfig):
        flag = _flag(ZENOH_FLAG_NAMES.get(f.name, f.name))
        out[f.name] = _flag(f"zenoh_{f.name}") if flag in section_flags else flag
    return out


def add_config_arguments(parser: argparse.ArgumentParser, section: str, cls: type,
                         with_zenoh: bool = True, zenoh_base: ZenohConfig | None = None) -> None:
    """Add ``--config``, one flag per field of ``cls``'s tree and the Zenoh flags to ``parser``.

    Flags default to ``argparse.SUPPRESS`` so that only given flags override file and env. Options
    are grouped by TOML table (``[planner]``, ``[planner.stomp]``, ...), each group naming its
    environment variables. The Zenoh session mode is always ``--zenoh-mode``; any other Zenoh field
    whose flag a section field already uses is offered as ``--zenoh-<name>`` instead. ``zenoh_base``:
    the command's own Zenoh defaults (as given to :func:`resolve_config`), shown in the help.
    """
    try:
        parser.add_argument("--config", metavar="FILE", default=None,
                            help=f"TOML config file (or ${ENV_PREFIX}_CONFIG)")
    except argparse.ArgumentError:  # the parser has its --config already (a tool with several sections)
        pass
    options = config_options(section, cls)
    tables = config_tables(section, cls)
    groups: dict[tuple[str, ...], ArgumentGroup] = {}
    for table, (text, _) in tables.items():
        if not any(o.table == table for o in options):
            continue
        env = "_".join((ENV_PREFIX, *table)).upper()
        flags = "" if len(table) == 1 else f", flags --{'.'.join(table[1:])}.<name>"
        groups[table] = parser.add_argument_group(f"[{'.'.join(table)}] options (env {env}_<NAME>{flags})",
                                                  text or None)
    for o in options:
        _add_flag(groups[o.table], o.flag, o)
    if with_zenoh:
        names = _zenoh_flags({o.flag for o in options})
        group = parser.add_argument_group(f"[zenoh] options (env {ENV_PREFIX}_ZENOH_<NAME>)")
        for o in config_options("zenoh", ZenohConfig):
            shown = o if zenoh_base is None else dataclasses.replace(o, default=getattr(zenoh_base, o.field))
            _add_flag(group, names[o.field], shown)


def _add_flag(group: ArgumentGroup, flag: str, o: Option) -> None:
    inner, is_list = base_type(o.tp)
    shown = ",".join(map(str, o.default)) if is_list else o.default
    text = f"{o.help} (default: {'empty' if shown == '' else shown})".replace("%", "%%")
    if inner is bool and not is_list:
        group.add_argument(flag, dest=o.dest, action=argparse.BooleanOptionalAction, default=argparse.SUPPRESS,
                           help=text)
    else:
        metavar = "{" + ",".join(map(str, o.choices)) + "}" if o.choices else o.field.upper()
        group.add_argument(flag, dest=o.dest, metavar=metavar, default=argparse.SUPPRESS, help=text)


def _check_tables(section: str, cls: type, data: dict[str, Any], source: str) -> None:
    """Raise ConfigError for unknown keys and non-table values of sub-tables in ``data`` (the section's table).

    ``source`` starts each message: the file that holds the table.
    """
    tables = config_tables(section, cls)
    for table, (_, allowed) in tables.items():
        values: Any = data
        for step in table[1:]:
            values = values.get(step, {}) if isinstance(values, dict) else {}
        if not isinstance(values, dict):
            raise ConfigError(f"{source}[{'.'.join(table)}]: must be a table, got {values!r}")
        unknown = sorted(set(values) - allowed)
        tables_named = [k for k in unknown if isinstance(values[k], dict)]  # [planner.stom]: a table, not an option
        if tables_named:
            subs = [".".join((*table, k)) for k in allowed if (*table, k) in tables]
            hint = closest(".".join((*table, tables_named[0])), subs)
            hint = hint.replace("mean ", "mean [").replace("?", "]?") if hint else ""
            raise ConfigError(f"{source}[{'.'.join((*table, tables_named[0]))}]: unknown table{hint}" + (
                f" ([{'.'.join(table)}] has {', '.join(f'[{t}]' for t in sorted(subs))})" if subs and not hint else ""))
        if unknown:
            hint = closest(unknown[0], allowed)
            raise ConfigError(f"{source}[{'.'.join(table)}]: unknown option(s) {', '.join(unknown)}{hint}")


def _apply(obj: Any, changes: dict[tuple[str, ...], Any]) -> Any:
    """``obj`` with the values of ``changes`` (attribute path -> value) set, nested configs replaced too."""
    direct = {path[0]: v for path, v in changes.items() if len(path) == 1}
    subs: dict[str, dict[tuple[str, ...], Any]] = {}
    for path, v in changes.items():
        if len(path) > 1:
            subs.setdefault(path[0], {})[path[1:]] = v
    for name, sub in subs.items():
        direct[name] = _apply(getattr(obj, name), sub)
    return dataclasses.replace(obj, **direct) if direct else obj


def _validate(obj: Any, name: str) -> None:
    """Run ``obj.validate`` (which validates its nested configs), else validate each nested config.

    A plain ValueError is named by its table (``name``).
    """
    validate = getattr(obj, "validate", None)
    if not callable(validate):
        for f, tp in fields_of(type(obj)):
            if is_config(tp):
                _validate(getattr(obj, f.name), name if f.metadata.get("inline") else f"{name}.{f.name}")
        return
    try:
        validate()
    except ConfigError:
        raise
    except ValueError as exc:
        raise ConfigError(f"{name}: {exc}") from None


def _resolve_section(section: str, cls: type[T], file_values: dict[str, Any],
                     env: typing.Mapping[str, str], cli: dict[str, Any], base: T | None = None,
                     cli_names: dict[str, str] | None = None, source: str = "") -> T:
    if not isinstance(file_values, dict):
        raise ConfigError(f"{source}[{section}] must be a table")
    _check_tables(section, cls, file_values, source)
    changes: dict[tuple[str, ...], Any] = {}
    given: dict[str, str] = {}  # option name -> where its value came from (for the checks' messages)
    for o in config_options(section, cls):
        flag = (cli_names or {}).get(o.field, o.flag)
        if o.dest in cli:
            if base_type(o.tp)[0] is Path and not str(cli[o.dest]).strip():  # cleared the file's value, unlike PATH=
                raise ConfigError(f"{flag}: empty; give a path (leave the flag out to keep the file's or the default)")
            changes[o.attrs], given[o.name] = parse_value(flag, o.tp, cli[o.dest], o.choices), flag
        elif o.env in env and not (base_type(o.tp)[0] is Path and not env[o.env].strip()):  # PATH= : unset
            changes[o.attrs], given[o.name] = parse_value(o.env, o.tp, env[o.env], o.choices), o.env
        else:
            raw = file_value(file_values, o)
            if raw is not dataclasses.MISSING:
                changes[o.attrs] = parse_value(f"{source}{o.name}", o.tp, raw, o.choices, typed=True)
                given[o.name] = source.rstrip(": ") or "the config file"
    obj = _apply(base if base is not None else cls(), changes)
    try:
        _validate(obj, section)
    except ConfigError as exc:  # name where the refused value was set: a file, a variable or a flag
        text = str(exc)
        named = max((n for n in given if text.startswith(n) and text[len(n):len(n) + 1] in (":", " ")), key=len,
                    default=None)
        if named is None:
            raise
        raise ConfigError(f"{text} (set by {given[named]})") from None
    return obj


def resolve_config(section: str, cls: type[T], args: argparse.Namespace | None = None,
                   env: typing.Mapping[str, str] | None = None,
                   config_file: str | os.PathLike[str] | None = None,
                   with_zenoh: bool = True, zenoh_base: ZenohConfig | None = None,
                   zenoh_fixed: tuple[str, ...] = ()) -> tuple[T, ZenohConfig]:
    """Resolve a section's config tree and the Zenoh config from defaults, file, env and CLI.

    Args:
        section: Section name, e.g. ``"replayer"``.
        cls: The section's dataclass.
        args: Parsed CLI namespace from a parser set up by :func:`add_config_arguments`.
        env: Environment mapping (default ``os.environ``).
        config_file: TOML file; overrides ``args.config`` and ``$FORESIGHT_CONFIG``.
        with_zenoh: Also resolve the ``[zenoh]`` section.
        zenoh_base: Defaults of the Zenoh section for this command (e.g. the router's listen endpoint).
        zenoh_fixed: Zenoh fields whose ``zenoh_base`` value the file and the variables leave (the router's mode:
            ``[zenoh]`` and ``FORESIGHT_ZENOH_*`` are the services' too); a flag still sets them.

    Returns:
        ``(section_config, zenoh_config)``.

    Raises:
        ConfigError: On any bad value, unknown option or unreadable file.
    """
    env = os.environ if env is None else env
    cli = dict(vars(args)) if args is not None else {}
    path = config_file or cli.get("config") or env.get(f"{ENV_PREFIX}_CONFIG")
    try:
        data = load_toml(path) if path else {}
    except ConfigError as exc:
        if config_file or cli.get("config"):
            raise
        raise ConfigError(f"{exc} (the file ${ENV_PREFIX}_CONFIG names)") from None  # a forgotten export, say
    source = f"config file {str(path)!r}: " if path else ""  # starts each message about what the file holds
    for key, value in data.items():
        if not isinstance(value, dict):
            raise ConfigError(f"{source}top-level key {key!r} must be a table like [{key}]")
    if section in SECTIONS:  # a section of the product (tests resolve sections of their own)
        check_file_sections(data, str(path))
    check_environment(env, {section: cls, **({"zenoh": ZenohConfig} if with_zenoh else {})})
    sec = _resolve_section(section, cls, data.get(section, {}), env, cli, source=source)
    names = _zenoh_flags({o.flag for o in config_options(section, cls)})
    zdata, zenv = data.get("zenoh", {}), env
    if zenoh_fixed:
        zdata = {k: v for k, v in zdata.items() if k not in zenoh_fixed}
        zenv = {k: v for k, v in env.items() if k not in {f"{ENV_PREFIX}_ZENOH_{n}".upper() for n in zenoh_fixed}}
    zen = (_resolve_section("zenoh", ZenohConfig, zdata, zenv, cli, zenoh_base, names, source)
           if with_zenoh else ZenohConfig())
    if not zen.role:  # the certificate a command presents by default: its own role, else the read-only observer
        zen = dataclasses.replace(zen, role=section if section in ROLES else OBSERVER)
    return sec, zen
