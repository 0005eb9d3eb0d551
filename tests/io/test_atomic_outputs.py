"""Outputs a kill can cut: the collections and indices are replaced whole, and a frame-times
line cut short is not read as a frame."""

from mpi4py import MPI

from fempm.io import vtu
from fempm.io.writers import FrameSeries


def test_a_collection_is_replaced_whole(tmp_path):
    path = tmp_path / "particles.pvd"
    vtu.write_collection(path, [(0.0, "a.pvtu")])
    vtu.write_collection(path, [(0.0, "a.pvtu"), (0.5, "b.pvtu")])
    text = path.read_text()
    assert text.endswith("</VTKFile>\n") and text.count("<DataSet") == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["particles.pvd"]  # no temporary left


def test_a_times_line_cut_by_a_kill_is_not_a_frame(tmp_path):
    (tmp_path / "particles").mkdir()
    (tmp_path / "particles" / "particles_times.csv").write_text("0,0.0\n1,0.5\n2,0.")
    series = FrameSeries(tmp_path, "particles", "particles", MPI.COMM_SELF)
    assert series.frames == [(0, 0.0), (1, 0.5)]
