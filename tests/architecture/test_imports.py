"""The package's import structure, read from the source with ``ast``: no import cycles, layers
that import only downward, and no fempm module imported inside a function (imports inside
functions are for optional dependencies only); the imports for annotations only (under
``if TYPE_CHECKING:``) are held to the same rules; no cycle between packages either."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "fempm"

#: the layers, lowest first: a module may import modules of its own layer or of lower ones
LAYERS = (
    ("fempm.arguments", "fempm.abort", "fempm.petsc", "fempm.docstrings", "fempm.timings"),
    ("fempm.kernels",),
    ("fempm.meshes",),
    ("fempm.materials",),
    ("fempm.particles",),
    ("fempm.transfer",),
    ("fempm.boundary", "fempm.colliders"),
    ("fempm.stepping",),
    ("fempm.implicit",),  # registers its step with the solver (fempm.stepping.solver.register_implicit_step)
    ("fempm.verification",),
    ("fempm.io",),
    ("fempm.scene",),
    ("fempm.scenes",),
    ("fempm.studies",),
    # the public surface: the CLI, the top-level namespace and the paths kept for existing imports
    ("fempm.cli", "fempm.__main__", "fempm", "fempm.domains", "fempm.manufactured", "fempm.errors",
     "fempm.contact"),
)


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def layer_of(module: str) -> int:
    """The index of the layer holding ``module`` (the longest matching prefix)."""
    best, length = None, -1
    for i, layer in enumerate(LAYERS):
        for prefix in layer:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > length:
                best, length = i, len(prefix)
    if best is None:
        raise AssertionError(f"{module} is in no layer of {__name__}.LAYERS: add it")
    return best


def is_type_checking(node: ast.If) -> bool:
    return "TYPE_CHECKING" in ast.unparse(node.test)


class Imports(ast.NodeVisitor):
    """The fempm modules a module imports at run time, those it imports for annotations only
    (under ``if TYPE_CHECKING:``), and those it imports inside functions."""

    def __init__(self, module: str, is_package: bool):
        self.package = module if is_package else module.rpartition(".")[0]
        self.runtime: set[str] = set()
        self.annotations: set[str] = set()
        self.in_functions: list[tuple[int, str]] = []
        self.depth = 0
        self.typing = False

    @property
    def all(self) -> set[str]:
        """Every fempm module imported, at run time or for annotations."""
        return self.runtime | self.annotations

    def visit_If(self, node: ast.If) -> None:
        if not is_type_checking(node):
            self.generic_visit(node)
            return
        self.typing = True  # imports for annotations only: not run, but part of the structure
        for child in node.body:
            self.visit(child)
        self.typing = False
        for child in node.orelse:
            self.visit(child)

    def visit_FunctionDef(self, node) -> None:
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_AsyncFunctionDef = visit_FunctionDef

    def add(self, target: str, line: int) -> None:
        if target in MODULES:
            (self.annotations if self.typing else self.runtime).add(target)
            if self.depth:
                self.in_functions.append((line, target))

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self.add(alias.name, node.lineno)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        base = node.module or ""
        if node.level:
            parent = self.package.split(".")[: len(self.package.split(".")) - node.level + 1]
            base = ".".join(parent + ([base] if base else []))
        for alias in node.names:
            sub = f"{base}.{alias.name}"
            self.add(sub if sub in MODULES else base, node.lineno)


def read_imports() -> dict[str, Imports]:
    out = {}
    for name, path in MODULES.items():
        visitor = Imports(name, path.name == "__init__.py")
        visitor.visit(ast.parse(path.read_text(), filename=str(path)))
        visitor.runtime.discard(name)
        visitor.annotations.discard(name)
        out[name] = visitor
    return out


IMPORTS = read_imports()


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_package_has_no_import_cycle():
    graph = {name: imp.runtime for name, imp in IMPORTS.items()}
    assert cycles(graph) == []


def test_no_cycle_through_the_imports_for_annotations():
    graph = {name: imp.all for name, imp in IMPORTS.items()}
    assert cycles(graph) == []


def package_of(module: str) -> str:
    """The subpackage holding ``module`` (``fempm.stepping.grid`` -> ``fempm.stepping``)."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and parts[1] in SUBPACKAGES else module


SUBPACKAGES = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}


def test_no_cycle_between_packages():
    graph: dict[str, set[str]] = {}
    for name, imp in IMPORTS.items():
        for target in imp.all:
            if package_of(target) != package_of(name):
                graph.setdefault(package_of(name), set()).add(package_of(target))
    assert cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_every_module_lies_in_a_layer():
    for name in MODULES:
        layer_of(name)


def test_layers_import_only_downward():
    upward = [f"{name} (layer {layer_of(name)}) imports {target} (layer {layer_of(target)})"
              for name, imp in IMPORTS.items() for target in sorted(imp.all)
              if layer_of(target) > layer_of(name)]
    assert upward == []


def test_no_fempm_module_is_imported_inside_a_function():
    inside = [f"{MODULES[name].relative_to(PACKAGE.parent)}:{line} imports {target}"
              for name, imp in IMPORTS.items() for line, target in imp.in_functions]
    assert inside == []


@pytest.mark.parametrize("source, expected", [
    ("def f():\n    from fempm import kernels\n", [(2, "fempm.kernels")]),
    ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from fempm.stepping import solver\n", []),
    ("import numpy\n", []),
])
def test_the_reader_sees_imports_in_functions_and_keeps_type_checking_apart(source, expected):
    visitor = Imports("fempm.x", False)
    visitor.visit(ast.parse(source))
    assert visitor.in_functions == expected
    assert visitor.annotations == ({"fempm.stepping.solver"} if "TYPE_CHECKING" in source else set())


def test_every_module_declares_its_public_names():
    """``__all__`` in every module that defines public names, and every name in it defined."""
    import importlib

    missing, undefined = [], []
    for name, path in MODULES.items():
        if name == "fempm.__main__":
            continue
        tree = ast.parse(path.read_text())
        declared = [n for n in tree.body if isinstance(n, ast.Assign)
                    and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)]
        defines = any(isinstance(n, (ast.FunctionDef, ast.ClassDef)) and not n.name.startswith("_") for n in tree.body)
        if not declared:
            if defines:
                missing.append(name)
            continue
        module = importlib.import_module(name)
        undefined += [f"{name}.{n}" for n in module.__all__ if not hasattr(module, n)]
    assert missing == [] and undefined == []
