"""The demos' pages of the site (docs/demo_runs.py): each demo's docstring, code and a run of
its DOCS_RUN made at build time, with what it printed and the figures it wrote; the run is kept
until the demo, its arguments or the package change; a failing demo fails the build."""

import importlib.util
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("demo_runs", ROOT / "docs" / "demo_runs.py")
demo_runs = importlib.util.module_from_spec(spec)
spec.loader.exec_module(demo_runs)

DEMO = textwrap.dedent('''
    """# A toy demo

    It prints a number and draws a figure.
    """
    import argparse
    from pathlib import Path

    DOCS_RUN = ["--n", "{n}"]


    def main(argv=None):
        ap = argparse.ArgumentParser()
        ap.add_argument("--n", type=int)
        ap.add_argument("--out", type=Path)
        args = ap.parse_args(argv)
        args.out.mkdir(parents=True, exist_ok=True)
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        plt.plot(range(args.n))
        plt.savefig(args.out / "line.png")
        for i in range(args.n):
            print(f"row {{i}}: {{i * i}}")
        if args.n < 0:
            raise SystemExit("negative n")


    if __name__ == "__main__":
        main()
''')


def write(tmp_path: Path, n: int) -> dict:
    demos = tmp_path / "demos"
    demos.mkdir(exist_ok=True)
    (demos / "toy.py").write_text(DEMO.format(n=n))
    (page,) = demo_runs.write_demo_pages(demos, tmp_path / "pages", tmp_path / "runs", execute=True)
    return {"page": page.read_text(), "key": (tmp_path / "runs" / "toy" / "run.key").read_text()}


def test_every_demo_gives_the_run_its_page_shows():
    for path in sorted((ROOT / "demos").glob("*.py")):
        args = demo_runs.docs_run(path.read_text())
        assert args and "--out" not in args, path.name


def test_a_demo_page_shows_its_code_and_a_run_made_at_build_time(tmp_path):
    first = write(tmp_path, 3)
    page = first["page"]
    assert page.startswith("# A toy demo") and "```python\nimport argparse" in page
    assert ".venv/bin/python demos/toy.py --n 3" in page
    assert "row 2: 4" in page and "![line](toy/line.png)" in page
    assert (tmp_path / "pages" / "toy" / "line.png").stat().st_size > 1000
    assert write(tmp_path, 3)["key"] == first["key"]  # kept: not run again
    longer = write(tmp_path, 100)
    assert longer["key"] != first["key"] and "row 99: 9801" in longer["page"]
    assert f"... ({100 - demo_runs.MAX_LINES} lines before)" in longer["page"] and "row 39: 1521" not in longer["page"]


def test_a_failing_demo_fails_the_build_naming_it(tmp_path):
    with pytest.raises(demo_runs.DemoRunError, match=r"demos/toy.py --n -1 exited with 1:(.|\n)*negative n"):
        write(tmp_path, -1)


def test_without_runs_the_pages_show_the_code(tmp_path):
    demos = tmp_path / "demos"
    demos.mkdir()
    (demos / "toy.py").write_text(DEMO.format(n=2))
    (page,) = demo_runs.write_demo_pages(demos, tmp_path / "pages", tmp_path / "runs", execute=False)
    assert "## The script" in page.read_text() and "## A run" not in page.read_text()
    assert not (tmp_path / "runs").exists()
