"""fempm.particles.migration.replace_rows: in-place removal and arrival of particle rows."""

import numpy as np

from fempm.particles.migration import pack, replace_rows, unpack


def test_rows_removed_and_added_keep_every_array_aligned():
    rng = np.random.default_rng(0)
    for _ in range(300):
        n = int(rng.integers(0, 30))
        h = int(rng.integers(0, n + 1)) if n else 0
        m = int(rng.integers(0, 12))
        holes = np.sort(rng.choice(n, h, replace=False)) if h else np.zeros(0, dtype=np.int64)
        arrays = {"a": np.arange(n, dtype=float), "b": np.arange(2 * n).reshape(n, 2)}
        arrivals = {"a": 100.0 + np.arange(m), "b": 1000 + np.arange(2 * m).reshape(m, 2)}
        out = replace_rows(arrays, holes, arrivals)
        kept = sorted(set(range(n)) - set(holes.tolist()))
        assert sorted(out["a"].tolist()) == sorted([float(k) for k in kept] + arrivals["a"].tolist())
        new = out["a"] >= 100
        assert np.array_equal(out["b"][:, 0], np.where(new, 1000 + 2 * (out["a"] - 100), 2 * out["a"]))
        assert np.array_equal(out["b"][:, 1], out["b"][:, 0] + 1)


def test_growth_reuses_the_spare_rows():
    arrays = {"a": np.arange(100, dtype=float)}
    out = replace_rows(arrays, np.array([3]), {"a": np.array([-1.0, -2.0])})  # grows: reallocated with slack
    assert len(out["a"]) == 101 and out["a"].base is not None and len(out["a"].base) > 101
    base = out["a"].base
    out = replace_rows(out, np.array([0]), {"a": np.array([-3.0, -4.0])})  # grows into the spare rows
    assert out["a"].base is base and sorted(out["a"])[:4] == [-4.0, -3.0, -2.0, -1.0]


def test_packed_rows_read_back_bit_for_bit():
    """pack/unpack (the byte rows that migration sends): every dtype and row shape, no rows."""
    rng = np.random.default_rng(1)
    for m in (0, 1, 7):
        data = {"x": rng.normal(size=(m, 2)), "cells": rng.integers(-5, 9, m).astype(np.int32),
                "F": rng.normal(size=(m, 2, 2)), "ids": rng.integers(0, 2**40, m), "flag": rng.random(m) < 0.5,
                "none": np.zeros((m, 0))}
        back = unpack(pack(data), {k: a[:0] for k, a in data.items()})
        assert list(back) == list(data)
        for k, a in data.items():
            assert back[k].dtype == a.dtype and back[k].shape == a.shape and back[k].flags.c_contiguous
            assert np.array_equal(back[k], a)


def test_sorted_particles_keep_spare_rows_for_arrivals():
    """After sort_by_cell a particle arriving from another rank reuses the spare rows."""
    from dolfinx.mesh import create_unit_square
    from mpi4py import MPI

    import fempm

    mesh = create_unit_square(MPI.COMM_SELF, 4, 4)
    x = np.random.default_rng(2).random((50, 2))
    p = fempm.Particles(mesh, x, 1.0, 1.0, fields={"v": np.zeros((50, 2))})
    p.sort_by_cell()
    assert np.all(np.diff(p.cells) >= 0) and np.array_equal(p.x, x[p.ids])
    bases = {k: a.base for k, a in {"x": p.x, "v": p.fields["v"], "ids": p.ids}.items()}
    assert all(b is not None and len(b) > 50 for b in bases.values())
    out = replace_rows({"x": p.x, "v": p.fields["v"], "ids": p.ids}, np.zeros(0, dtype=np.int64),
                       {"x": np.full((1, 2), 0.5), "v": np.ones((1, 2)), "ids": np.array([99])})
    assert all(out[k].base is bases[k] for k in out) and out["ids"][-1] == 99
