"""Reading fempm's docstrings as reference text: the ``Args:`` section of a function or class
(Google style, as the public API writes them) and Sphinx markup made plain, for the command
line's help (``python -m fempm run SCENE --help``)."""

from __future__ import annotations

import inspect
import re

__all__ = ["arguments", "first_sentence", "plain"]

_SECTION = re.compile(r"^(\s*)(Args|Arguments|Parameters):\s*$")
_ENTRY = re.compile(r"^(\s+)(\*{0,2}\w+)(\s*\([^)]*\))?:\s*(.*)$")
_ROLE = re.compile(r":(?:math|class|func|meth|mod|attr|data|exc|ref|obj):`~?([^`]*)`")


def arguments(obj) -> dict[str, str]:
    """The entries of ``obj``'s ``Args:`` section, name -> description (continuation lines
    joined with single spaces, markup kept); {} without one."""
    lines = (inspect.getdoc(obj) or "").splitlines()
    out: dict[str, str] = {}
    inside, indent, name = False, None, None
    for line in lines:
        section = _SECTION.match(line)
        if section:
            inside, indent, name = True, None, None
            continue
        if not inside:
            continue
        if line.strip() and not line.startswith(" "):  # the next section
            break
        entry = _ENTRY.match(line)
        if entry and (indent is None or len(entry.group(1)) == indent):
            indent, name = len(entry.group(1)), entry.group(2)
            out[name] = entry.group(4).strip()
        elif name is not None and line.strip():
            out[name] += " " + line.strip()
    return out


def plain(text: str) -> str:
    """``text`` without Sphinx markup, on one line: a role as its text (``:math:`\\rho``` ->
    ``\\rho``; ``:class:`~a.B``` -> ``B``), double backquotes dropped."""

    def role(m: re.Match) -> str:
        target = m.group(1)
        return target.split(".")[-1] if m.group(0).count("~") and not m.group(0).startswith(":math") else target

    return " ".join(_ROLE.sub(role, text).replace("``", "").split())


def first_sentence(text: str) -> str:
    """The first sentence of ``text``: up to the first period that ends a sentence outside
    parentheses (a period followed by a space or the end)."""
    depth = 0
    for i, c in enumerate(text):
        depth += (c in "([") - (c in ")]")
        if c == "." and depth == 0 and (i + 1 == len(text) or text[i + 1] == " "):
            return text[: i + 1]
    return text
