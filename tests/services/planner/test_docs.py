"""docs/planner.md's option table names every option of the planner service, and no other."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from services.planner.config import PlannerServiceConfig

DOC = Path(__file__).resolve().parents[3] / "docs" / "planner.md"


def _options(cls: type, prefix: str = "", hide: tuple[str, ...] = ()) -> set[str]:
    """Every option of ``cls`` (``stomp.waypoints``): nested configs' fields less hidden ones."""
    names: set[str] = set()
    for f in dataclasses.fields(cls):
        if f.name in hide:
            continue
        if "inline" in f.metadata:  # a nested config (shared.config_tree.nested)
            inner = prefix if f.metadata["inline"] else f"{prefix}{f.name}."
            names |= _options(f.default_factory, inner, f.metadata["hide"])
        else:
            names.add(prefix + f.name)
    return names


def _table_rows(text: str) -> set[str]:
    """The option names in the first column of the table under ``| option | default | meaning |``."""
    lines = text.splitlines()
    start = lines.index("| option | default | meaning |") + 2  # past the header and its rule
    names: set[str] = set()
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        names |= {n.strip() for n in line.split("|")[1].split(",")}
    return names


def test_the_option_table_lists_every_planner_option() -> None:
    """``goal_choice`` was in the text (its section) but not the table: the table's rows themselves are checked."""
    options, rows = _options(PlannerServiceConfig), _table_rows(DOC.read_text())
    assert "stomp.waypoints" in options and "goal_choice" in options and "stomp.seed" not in options
    assert sorted(options - rows) == [], "options missing from docs/planner.md's table"
    assert sorted(rows - options) == [], "rows of docs/planner.md's table that are no option"
