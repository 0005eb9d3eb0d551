"""Sphinx configuration of fempm's site: the docs pages (MyST markdown), the API reference
from the docstrings (autodoc, Google-style Args: sections through napoleon) and the demos, each
rendered from its own source (its markdown docstring, then its code) with a run of it made at
build time (docs/demo_runs.py; FEMPM_DOCS_DEMOS=code leaves the runs out). ``make docs`` builds it
into ``docs/_build/html``; ``make test`` builds it with warnings as errors."""

import sys
from pathlib import Path

import fempm  # noqa: F401  (before dolfinx: the wheel's MPI first)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import demo_runs  # noqa: E402  (docs/demo_runs.py: the demos run when the site is built)

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
exclude_patterns = ["_build", "demo_runs.py"]
# the demos' result tables (docs/<demo>/*.md) start with their provenance line, not a title: the
# pages link to them, and the hidden toctree that holds them has no title to show
suppress_warnings = ["toc.no_title"]
html_theme = "alabaster"
html_title = "fempm"


def write_demo_pages(app) -> None:
    """docs/demos/<name>.md from demos/<name>.py, each with a run made at build time
    (:mod:`demo_runs`)."""
    demo_runs.write_demo_pages()


def setup(app):
    app.connect("builder-inited", write_demo_pages)
