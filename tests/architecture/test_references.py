"""Every file the package's code and docstrings point to exists in the repository, and none
points to documents that are not in it."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCES = sorted((ROOT / "fempm").rglob("*.py"))
PATH = re.compile(r"\b((?:docs|tests|benchmarks|demos|scripts|meshes)/[\w./-]*\w)")


def test_referenced_files_exist():
    missing, seen = [], 0
    for source in SOURCES:
        for match in PATH.finditer(source.read_text()):
            seen += 1
            target = match.group(1).rstrip(".")
            if "*" not in target and not (ROOT / target).exists():
                missing.append(f"{source.relative_to(ROOT)}: {target}")
    assert seen > 20 and missing == []  # the code points to its docs, tests and benchmarks


def test_no_reference_to_documents_outside_the_repository():
    outside = [f"{s.relative_to(ROOT)}" for s in SOURCES
               if re.search(r"VERIFICATION\.md|DESIGN\.md|\bseed 00\d", s.read_text())]
    assert outside == []
