"""The package's sizes, read from the source with ``ast``: no function over 80 lines of code (its
docstring not counted) and no module over 400 lines in ``fempm/`` (a longer one does more than
one thing; split it into named parts)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "fempm"
MAX_FUNCTION, MAX_MODULE = 80, 400
FILES = sorted(PACKAGE.rglob("*.py"))


def functions(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def length(f: ast.FunctionDef) -> int:
    """The function's lines, less its docstring's."""
    lines = f.end_lineno - f.lineno + 1
    first = f.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        lines -= first.end_lineno - first.lineno + 1
    return lines


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_functions_and_modules_are_short(path):
    source = path.read_text()
    lines = len(source.splitlines())
    assert lines <= MAX_MODULE, f"{path.name}: {lines} lines (at most {MAX_MODULE})"
    long = [f"{f.name} ({length(f)} lines, line {f.lineno})" for f in functions(ast.parse(source))
            if length(f) > MAX_FUNCTION]
    assert not long, f"{path.name}: over {MAX_FUNCTION} lines: {', '.join(long)}"


def test_the_measure_counts_code_not_the_docstring():
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION))
    (f,) = functions(ast.parse(f"def f():\n{body}\n"))
    assert length(f) == MAX_FUNCTION + 1
    (g,) = functions(ast.parse(f'def g():\n    """A\n\n    B\n    """\n{body}\n'))
    assert length(g) == MAX_FUNCTION + 1


def positional_counts() -> list[tuple[int, str]]:
    """(positional parameters, "module:function") of every function in fempm."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                out.append((len(node.args.posonlyargs) + len(node.args.args),
                            f"{path.relative_to(PACKAGE.parent)}:{node.name}"))
    return out


def test_no_function_takes_more_than_12_positional_parameters():
    """Options go by keyword (the scenes' builders take theirs keyword-only); the compiled
    passes take their arrays in named bundles (fempm.kernels.bundles), their inlined helpers
    small tuples."""
    many = [f"{where} ({k})" for k, where in positional_counts() if k > 12]
    assert many == []
