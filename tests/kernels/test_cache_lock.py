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


_WORKLOAD = """
import json, sys
from numba.core import event
import fempm
from fempm.scenes import two_disks
from fempm.stepping import StepOptions

compiled = []

class Listener(event.Listener):
    def on_start(self, ev):
        pass
    def on_end(self, ev):
        f = getattr(ev.data.get("dispatcher"), "py_func", None)
        if f is not None and f.__module__.startswith("fempm."):
            compiled.append(f.__module__ + "." + f.__qualname__)

event.register("numba:compile", Listener())
for domain in ("cpdi1", "ugimp"):  # CPDI1: the planar sample passes and corner location; uGIMP: the box pieces
    scene = two_disks(mesh="structured", cells=6, t_end=1.0)
    scene.options = StepOptions(scheme="USL", domain=domain)
    solver = scene.solver()
    solver.step()
json.dump(compiled, sys.stdout)
"""


def test_a_second_process_loads_every_kernel_from_the_cache(tmp_path):
    """A kernel whose cache key changes from process to process (a compiled helper held in its
    closure pickles with a random id) compiles again in every process and every MPI rank: the
    second process with the same cache must compile nothing of fempm's."""
    import json
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    runs = [subprocess.run([sys.executable, "-c", _WORKLOAD], capture_output=True, text=True, env=env, timeout=600)
            for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr[-2000:]
    first, second = (json.loads(r.stdout.strip().splitlines()[-1]) for r in runs)
    assert any("planar_samples" in name for name in first) and any("boxes" in name for name in first), first
    assert second == [], second


_VARIANTS = """
import functools, sys
import numpy as np
from numba import njit
if sys.argv[1] == "fempm":
    from fempm.kernels import cache_lock
    assert cache_lock.distinct_variant_ids()

@functools.cache
def make(dtype):
    @njit(cache=True)
    def full(n):
        return np.ones(n, dtype=dtype)  # (boxing the result reads the variant's dtype from its environment)
    return full

for name in sys.argv[2:]:
    print(name, make(np.dtype(name))(3).dtype, make(np.dtype(name)).stats.cache_hits.total())
"""


def _variants(tmp_path, mode: str, *names: str, cache: str | None = None) -> list[str]:
    import os
    import subprocess
    import sys

    script = tmp_path / "variants.py"
    script.write_text(_VARIANTS)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / f"cache-{cache or mode}"))
    out = subprocess.run([sys.executable, str(script), mode, *names], env=env, capture_output=True, text=True,
                         timeout=300)
    return out.stdout.split("\n") if out.returncode == 0 else ["failed: " + out.stderr.strip().splitlines()[-1]]


def test_variants_compiled_in_two_processes_keep_their_own_names(tmp_path):
    """Two processes each compile one variant of a factory's kernel first (the same count of
    numba's ids in both); a third loads both from the cache. With fempm's names each keeps its
    own environment; with numba's alone the second finds the first's (numba's ``_rebuild_env``)."""
    for mode in ("fempm", "numba"):
        assert _variants(tmp_path, mode, "int64")[0] == "int64 int64 0"
        assert _variants(tmp_path, mode, "float32")[0] == "float32 float32 0"
    assert _variants(tmp_path, "fempm", "int64", "float32")[:2] == ["int64 int64 1", "float32 float32 1"]
    assert _variants(tmp_path, "numba", "int64", "float32")[:2] != ["int64 int64 1", "float32 float32 1"]
    # code saved with numba's names is not loaded with fempm's: compiled anew, then loaded
    assert _variants(tmp_path, "fempm", "int64", "float32", cache="numba")[:2] == ["int64 int64 0", "float32 float32 0"]
    assert _variants(tmp_path, "fempm", "int64", "float32", cache="numba")[:2] == ["int64 int64 1", "float32 float32 1"]
