"""numba's on-disk cache under concurrent writers (fempm.kernels.cache_lock): two processes
save two entries of one cache index at the same time, each slowed between reading the index
and writing it (the window of the race); each entry must load back its own data. Without
the lock both take the data file number 1 and one entry loads the other's data."""

import multiprocessing as mp
import time

import pytest

pytest.importorskip("numba")


def _save(path, key, value, locked, barrier):
    from numba.core import caching

    if locked:  # (importing fempm.kernels installs the lock)
        from fempm.kernels import cache_lock

        assert cache_lock.install()
    load_index = caching.IndexDataCacheFile._load_index

    def slow_load_index(self):  # both processes read the index before either writes it
        index = load_index(self)
        time.sleep(0.3)
        return index

    caching.IndexDataCacheFile._load_index = slow_load_index
    cache = caching.IndexDataCacheFile(path, "kernel", ("stamp", 1))
    barrier.wait()
    cache.save(key, value)


def _race(path, locked: bool) -> list:
    from numba.core import caching

    ctx = mp.get_context("spawn")
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_save, args=(path, key, key.upper(), locked, barrier)) for key in ("a", "b")]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    cache = caching.IndexDataCacheFile(path, "kernel", ("stamp", 1))
    return [cache.load(key) for key in ("a", "b")]


def test_concurrent_cache_saves_keep_each_kernel_its_own_data(tmp_path):
    (tmp_path / "locked").mkdir()
    assert _race(str(tmp_path / "locked"), locked=True) == ["A", "B"]
    (tmp_path / "unlocked").mkdir()
    assert _race(str(tmp_path / "unlocked"), locked=False) != ["A", "B"]  # the race the lock prevents
