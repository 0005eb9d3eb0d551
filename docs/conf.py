"""Sphinx configuration of fempm's site: the docs pages (MyST markdown), the API reference
from the docstrings (autodoc, Google-style Args: sections through napoleon) and the demos, each
rendered from its own source (its markdown docstring, then its code). ``make docs`` builds it
into ``docs/_build/html``; ``make test`` builds it with warnings as errors."""

import ast
from pathlib import Path

import fempm  # noqa: F401  (before dolfinx: the wheel's MPI first)

HERE = Path(__file__).resolve().parent
DEMOS = HERE.parent / "demos"

project = "fempm"
author = "the fempm developers"
extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.mathjax", "myst_parser"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3
autodoc_typehints = "none"
autodoc_member_order = "bysource"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
exclude_patterns = ["_build"]
# the demos' result tables (docs/<demo>/*.md) start with their provenance line, not a title: the
# pages link to them, and the hidden toctree that holds them has no title to show
suppress_warnings = ["toc.no_title"]
html_theme = "alabaster"
html_title = "fempm"


def demo_page(path: Path) -> str:
    """A demo as a page: its module docstring (markdown), then its code, then how to run it."""
    source = path.read_text()
    tree = ast.parse(source)
    doc = ast.get_docstring(tree) or f"# {path.stem}"
    body = source.splitlines()[tree.body[0].end_lineno:] if ast.get_docstring(tree) else source.splitlines()
    code = "\n".join(body).strip("\n")
    return (f"{doc}\n\n## The script\n\n`demos/{path.name}`; run it with `.venv/bin/python demos/{path.name} --help` "
            f"for its options.\n\n```python\n{code}\n```\n")


def write_demo_pages(app) -> None:
    """docs/demos/<name>.md from demos/<name>.py (generated, not kept in git)."""
    out = HERE / "demos"
    out.mkdir(exist_ok=True)
    for path in sorted(DEMOS.glob("*.py")):
        page = out / f"{path.stem}.md"
        text = demo_page(path)
        if not page.exists() or page.read_text() != text:
            page.write_text(text)


def setup(app):
    app.connect("builder-inited", write_demo_pages)
