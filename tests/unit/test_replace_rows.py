"""fempm.migration.replace_rows: in-place removal and arrival of particle rows."""

import numpy as np

from fempm.migration import replace_rows


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
