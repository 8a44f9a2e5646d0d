"""Declaring a config tree (:func:`opt`, :func:`nested`) and walking it: one :class:`Option` per field.

A config is a dataclass whose fields are declared with :func:`opt` (help text, choices) and whose
nested component configs are declared with :func:`nested`. :func:`config_options` lists every
configurable field of a section's tree with its TOML table, environment variable, flag and help;
:func:`parse_value` converts a raw value (a string from the environment or the command line, or a
TOML value) to a field's type. :mod:`shared.config` loads the tree from file, environment and flags.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["ENV_PREFIX", "ConfigError", "opt", "nested", "parse_value", "base_type", "Option", "config_options",
           "config_tables", "fields_of", "is_config", "file_value"]

ENV_PREFIX = "FORESIGHT"

_INT = re.compile(r"[ \t]*[+-]?[0-9]+(\.0*)?[ \t]*")
"""An integer written as text (a variable, a flag): ASCII digits, perhaps ``.0`` as a file may write it."""
_FLOAT = re.compile(r"[ \t]*[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?[ \t]*")
"""A number written as text: decimal or exponent notation in ASCII (no ``_``, ``inf`` or ``nan``)."""


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


def nested(cls: type, *, help: str = "", inline: bool = False, hide: Sequence[str] = (),
           field_help: dict[str, str] | None = None) -> Any:
    """Declare a nested component config (a dataclass field holding another config dataclass).

    Args:
        cls: The component's config dataclass (its default is ``cls()``).
        help: What the component is (shown above its options in ``--help``).
        inline: Share the parent's table, environment names and flags instead of a sub-table.
        hide: Fields of ``cls`` the parent sets itself: not read from file, environment or flags.
        field_help: Help texts replacing those of ``cls`` for some fields (where the parent gives a
            field another meaning, e.g. another default).

    The parent's ``validate`` validates the nested config (naming its fields ``<section>.<name>.<field>``).

    Returns:
        A ``dataclasses.field``.
    """
    meta = {"help": help, "inline": inline, "hide": tuple(hide), "field_help": dict(field_help or {})}
    return dataclasses.field(default_factory=cls, metadata=meta)


# ----------------------------------------------------------------------------------------------
# value parsing


def base_type(tp: Any) -> tuple[Any, bool]:
    """Return (inner type, is_list) for a field annotation (``X``, ``list[X]``, ``X | None``)."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return base_type(args[0])
    if origin is list:
        return typing.get_args(tp)[0], True
    return tp, False


def parse_value(name: str, tp: Any, raw: Any, choices: Sequence[Any] | None = None, typed: bool = False) -> Any:
    """Convert ``raw`` (a string from env/CLI, or a TOML value) to the field type ``tp``.

    Args:
        name: Dotted option name used in error messages, e.g. ``replayer.rate_hz``.
        tp: The field's annotation (resolved).
        raw: The value to convert.
        choices: Allowed values, if any.
        typed: ``raw`` comes from a file that has types of its own (TOML): a number or a boolean written as a
            string (``steps = "20"``) is refused, as TOML's own readers would (only env and flags are text).

    Returns:
        The converted value.

    Raises:
        ConfigError: If the value cannot be converted or is not among ``choices``.
    """
    inner, is_list = base_type(tp)
    if is_list:
        if isinstance(raw, str):
            items = [s.strip() for s in raw.split(",") if s.strip()]
        elif isinstance(raw, list | tuple):
            items = list(raw)
        else:
            raise ConfigError(f"{name}: expected a list, got {raw!r}")
        return [parse_value(name, inner, item, choices, typed) for item in items]
    if typed and isinstance(raw, str) and inner in (bool, int, float):
        raise ConfigError(f"{name}: expected {inner.__name__}, got the string {raw!r} (in TOML write "
                          f"{'true or false' if inner is bool else 'the number'} without quotes)")
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
            if isinstance(raw, str):  # a variable or a flag: what a file may hold, 5 or 5.0, but no 1_000 or "٣"
                if not _INT.fullmatch(raw):
                    raise ValueError
                raw = raw.strip().split(".")[0]
            value = int(raw)
        elif inner is float:
            if isinstance(raw, bool) or (isinstance(raw, str) and not _FLOAT.fullmatch(raw)):
                raise ValueError
            value = float(raw)
            if value != value or value in (float("inf"), float("-inf")):
                raise ValueError
        elif inner is Path:
            if not isinstance(raw, str | Path):
                raise ValueError
            if not str(raw).strip():  # FORESIGHT_REPLAYER_LIBRARY= : unset, not the current directory
                if type(None) in typing.get_args(tp):
                    return None
                raise ConfigError(f"{name}: an empty path")
            try:
                value = Path(str(raw)).expanduser()
            except RuntimeError:  # '~user' of no such user, or '~' without a home directory
                raise ConfigError(f"{name}: cannot expand '~' in {str(raw)[:200]!r} (no such user, or no home "
                                  "directory); give the path in full") from None
        elif inner is str:
            if not isinstance(raw, str):
                raise ValueError
            value = raw
        else:  # pragma: no cover - config dataclasses only use the types above
            raise ConfigError(f"{name}: unsupported option type {inner!r}")
    except ConfigError:  # already names what is wrong
        raise
    except (TypeError, ValueError):
        kind = getattr(inner, "__name__", str(inner))
        raise ConfigError(f"{name}: expected {kind}, got {raw!r}") from None
    if choices is not None and value not in choices:
        raise ConfigError(f"{name}: {value!r} is not one of {', '.join(map(str, choices))}")
    return value


# ----------------------------------------------------------------------------------------------
# the option tree


@dataclasses.dataclass(frozen=True)
class Option:
    """One configurable field of a section's config tree.

    Attributes:
        attrs: Attribute path from the section's dataclass, e.g. ``("planner", "stomp", "iterations")``.
        table: TOML table path, e.g. ``("planner", "stomp")`` (inline configs add no step).
        tp: The field's (resolved) annotation.
        choices: Allowed values, or None.
        help: Help text.
        default: The default value.
    """

    attrs: tuple[str, ...]
    table: tuple[str, ...]
    tp: Any
    choices: tuple[Any, ...] | None
    help: str
    default: Any

    @property
    def field(self) -> str:
        """The field name."""
        return self.attrs[-1]

    @property
    def name(self) -> str:
        """Dotted name used in messages, e.g. ``planner.stomp.iterations``."""
        return ".".join((*self.table, self.field))

    @property
    def env(self) -> str:
        """The environment variable, e.g. ``FORESIGHT_PLANNER_STOMP_ITERATIONS``."""
        return "_".join((ENV_PREFIX, *self.table, self.field)).upper()

    @property
    def flag(self) -> str:
        """The command-line flag relative to the section, e.g. ``--stomp.iterations`` (``--rate-hz``)."""
        return "--" + ".".join((*self.table[1:], self.field)).replace("_", "-")

    @property
    def dest(self) -> str:
        """The argparse destination."""
        return "__".join((*self.table, self.field))


def _field_docs(cls: type) -> dict[str, str]:
    """Help texts of ``cls``'s fields from its docstring's ``Attributes:`` section and trailing comments."""
    docs: dict[str, str] = {}
    try:
        for m in re.finditer(r"^\s+(\w+)\s*:[^=#\n]*=[^#\n]*#\s*(.+)$", inspect.getsource(cls), re.M):
            docs[m.group(1)] = m.group(2).strip()
    except (OSError, TypeError):  # no source (e.g. built in an interpreter)
        pass
    text = inspect.cleandoc(cls.__doc__ or "")
    block = re.search(r"^Attributes:\n((?:[ \t]+\S.*\n?|\n)+)", text, re.M)
    if block:
        name = None
        for line in block.group(1).splitlines():
            m = re.match(r"^\s{4}(\w+)(?:\s*\([^)]*\))?:\s*(.*)$", line)
            if m:
                name = m.group(1)
                docs[name] = m.group(2).strip()
            elif name and line.strip():
                docs[name] += " " + line.strip()
    return docs


def _plain(text: str) -> str:
    """A docstring fragment as help text: no reST roles or double backticks, no final period."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"\1", text).replace("``", "`")
    return text[:-1] if text.endswith(".") and not text.endswith("..") else text


def is_config(tp: Any) -> bool:
    """Whether the annotation ``tp`` is a nested config (a dataclass type)."""
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def config_options(section: str, cls: type) -> list[Option]:
    """Every configurable field of ``cls``'s tree, in declaration order (nested configs after their parent's fields).

    Raises:
        ValueError: If two fields would share an environment variable or a flag (a config bug).
    """
    out: list[Option] = []

    def walk(kls: type, default: Any, attrs: tuple[str, ...], table: tuple[str, ...], hide: tuple[str, ...],
             help_over: dict[str, str]) -> None:
        docs = _field_docs(kls)
        later: list[tuple[dataclasses.Field[Any], Any]] = []
        for f, tp in fields_of(kls):
            if f.name in hide:
                continue
            if is_config(tp):
                later.append((f, tp))
                continue
            text = _plain(help_over.get(f.name) or f.metadata.get("help") or docs.get(f.name, ""))
            choices = f.metadata.get("choices")
            out.append(Option((*attrs, f.name), table, tp, tuple(choices) if choices else None, text,
                              getattr(default, f.name)))
        for f, tp in later:  # inline configs first: their fields read as the parent's own
            if f.metadata.get("inline"):
                walk(tp, getattr(default, f.name), (*attrs, f.name), table, f.metadata.get("hide", ()),
                     f.metadata.get("field_help", {}))
        for f, tp in later:
            if not f.metadata.get("inline"):
                walk(tp, getattr(default, f.name), (*attrs, f.name), (*table, f.name), f.metadata.get("hide", ()),
                     f.metadata.get("field_help", {}))

    walk(cls, cls(), (), (section,), (), {})
    for key in ("env", "flag"):
        seen: dict[str, Option] = {}
        for o in out:
            other = seen.setdefault(getattr(o, key), o)
            if other is not o:
                raise ValueError(f"config {section}: {other.name} and {o.name} share {key} {getattr(o, key)}")
    return out


def config_tables(section: str, cls: type) -> dict[tuple[str, ...], tuple[str, set[str]]]:
    """``table path -> (help, allowed keys)`` of ``cls``'s tree (sub-table names count as keys)."""
    tables: dict[tuple[str, ...], tuple[str, set[str]]] = {(section,): ("", set())}

    def walk(kls: type, table: tuple[str, ...], hide: tuple[str, ...]) -> None:
        for f, tp in fields_of(kls):
            if f.name in hide:
                continue
            if not is_config(tp):
                tables[table][1].add(f.name)
            elif f.metadata.get("inline"):
                walk(tp, table, f.metadata.get("hide", ()))
            else:
                sub = (*table, f.name)
                tables[table][1].add(f.name)
                tables[sub] = (f.metadata.get("help", ""), set())
                walk(tp, sub, f.metadata.get("hide", ()))

    walk(cls, (section,), ())
    return tables


def fields_of(cls: type) -> list[tuple[dataclasses.Field[Any], Any]]:
    """``(field, resolved annotation)`` of each field of the dataclass ``cls``."""
    hints = typing.get_type_hints(cls)
    return [(f, hints[f.name]) for f in dataclasses.fields(cls)]


def file_value(data: dict[str, Any], o: Option) -> Any:
    """``o``'s value in ``data``, its section's table of a config file; ``dataclasses.MISSING`` where it holds none."""
    values: Any = data
    for step in o.table[1:]:
        values = values.get(step, {}) if isinstance(values, dict) else {}
    return values.get(o.field, dataclasses.MISSING) if isinstance(values, dict) else dataclasses.MISSING
