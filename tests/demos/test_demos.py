"""Every demo runs at a small size and checks a number."""

import importlib.util
from pathlib import Path

import pytest
from mpi4py import MPI

DEMOS = Path(__file__).resolve().parents[2] / "demos"


def load(name):
    """Import a demo script as a module."""
    spec = importlib.util.spec_from_file_location(name, DEMOS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_projection_demo(tmp_path):
    demo = load("projection_unstructured")
    out = tmp_path / "projection"
    res = demo.main(["--ppc", "4", "--out", str(out)])
    cases = {(c["space"], c["mass"]): c for c in res["cases"]}
    assert res["area"] == pytest.approx(1 - 0.04 * 3.14159, rel=3e-3)
    for c in cases.values():
        assert c["mass defect"] < 1e-13 and c["momentum defect"] < 1e-12
    # consistent beats lumped on P1, and P2 beats P1 on this smooth field
    assert cases["P1", "consistent"]["L2 error"] < 0.5 * cases["P1", "lumped"]["L2 error"]
    assert cases["P2", "consistent"]["L2 error"] < 0.2 * cases["P1", "consistent"]["L2 error"]
    if MPI.COMM_WORLD.rank == 0:
        assert (out / "projection.png").stat().st_size > 10_000
        assert (out / "f_P2_consistent.bp").is_dir()


def test_two_disks_demo_writes_outputs(tmp_path):
    demo = load("two_disks")
    out = tmp_path / "disks"
    res = demo.main(["--mesh", "structured", "--t-end", "0.5", "--out", str(out)])
    assert res["momentum_drift"] < 1e-13
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert len(frames) == len(list((out / "particles").glob("particles_*.pvtu"))) > 3
    rows = (out / "energies.csv").read_text().splitlines()
    assert len(rows) == res["steps"] + 1 and rows[0].startswith("step,dt,t,kinetic,strain,total")
    assert (out / "energies.png").stat().st_size > 10_000 and (out / "summary.json").exists()
    assert (out / "grid_velocity.pvd").is_file() and (out / "grid_stress.pvd").is_file()
