"""No module reaches into another object's private members (``obj._name`` for any ``obj`` but
``self`` or ``cls``), read from the source with ``ast``. DOLFINx's ``_cpp_object`` is the one
exception: DOLFINx's own Python layer passes its C++ objects that way."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "fempm"
ALLOWED = {"_cpp_object"}


def private_uses(source: str) -> list[str]:
    uses = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            if node.attr not in ALLOWED:
                uses.append(f"line {node.lineno}: {ast.unparse(node)}")
    return uses


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_no_private_members_of_other_objects(path):
    assert not private_uses(path.read_text()), f"{path.name}: {private_uses(path.read_text())}"


def test_the_check_finds_one():
    assert private_uses("def f(solver):\n    return solver._grid\n") == ["line 2: solver._grid"]
    assert private_uses("class A:\n    def f(self):\n        return self._grid\n") == []
