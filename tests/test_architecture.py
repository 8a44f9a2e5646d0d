"""The tree's rules (issue 14): no module reads another object's underscore attributes, and no source
module grows past 400 lines."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("services", "shared", "tools")
MAX_LINES = 400
# Names that are public API despite the underscore (namedtuple's methods, os._exit, and aten's registered
# operator torch.ops.aten._unsafe_index: the unchecked gather inductor itself lowers indexing to).
PUBLIC_UNDERSCORE = {"_replace", "_asdict", "_fields", "_make", "_field_defaults", "_exit", "_unsafe_index"}


def _sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES if (ROOT / pkg).is_dir() for p in (ROOT / pkg).rglob("*.py"))


def private_reads(source: str) -> list[tuple[int, str]]:
    """Reads of another object's ``_name`` attributes and imports of another module's ``_name``.

    ``self._x``, ``cls._x`` and ``super()._x`` are the object's own; dunders are Python's.
    """
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute):
            name = node.attr
            if not name.startswith("_") or name.startswith("__") or name in PUBLIC_UNDERSCORE:
                continue
            owner = node.value
            if isinstance(owner, ast.Name) and owner.id in ("self", "cls"):
                continue
            if isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name) and owner.func.id == "super":
                continue
            found.append((node.lineno, f"{ast.unparse(owner)}.{name}"))
        elif isinstance(node, ast.ImportFrom):
            found += [(node.lineno, f"from {node.module} import {a.name}") for a in node.names
                      if a.name.startswith("_") and not a.name.startswith("__")]
    return sorted(found)


def test_the_scan_sees_a_private_read_and_lets_own_attributes_pass() -> None:
    code = "class A:\n    def f(self, other):\n        return self._a + other._b + super()._c\nfrom m import _d\n"
    assert private_reads(code) == [(3, "other._b"), (4, "from m import _d")]


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_reads_another_objects_underscore_attributes(path: Path) -> None:
    assert private_reads(path.read_text()) == []


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_source_module_is_over_400_lines(path: Path) -> None:
    assert len(path.read_text().splitlines()) <= MAX_LINES
