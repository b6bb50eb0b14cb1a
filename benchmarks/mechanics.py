"""Benchmark: build and load the PDMS mechanics table (issue 2 targets).

Run with ``python benchmarks/mechanics.py [--repeat 5]``.  Prints one table
row per case with the median wall time of ``--repeat`` runs, the target, the
ratio median/target, the peak traced heap (tracemalloc, which also traces numpy
buffers; measured in a separate untimed run), and the number of shooting passes (calls of
``osmobulge.modeling._shooting.shoot``) and integrated rows per build.

Cases
-----
* ``bulge_mechanics`` over ``linspace(0.005, 7, 200)`` from scratch (in-process
  caches cleared before each run);
* the same with the in-process memos (locking volumes, guess families) kept warm;
* ``mechanics_table(PDMS, vtilde_max=7, n=200, cache=False)`` from scratch
  (the table's own Chebyshev grid plus the locking volume and the splines);
* ``mechanics_table(PDMS, vtilde_max=7, n=200)`` loaded from a warm on-disk
  cache in a fresh temporary ``OSMOBULGE_CACHE_DIR``.

Targets (issue 2): < 1 s from scratch on one core, < 10 ms from cache.

The run is pinned to one core honestly: BLAS/OpenMP thread counts are set to
1 before numpy is imported and, where the OS allows it, the process affinity
is restricted to a single CPU.  On a shared machine the load average is
printed too, because other processes on the same core inflate the times.
"""

from __future__ import annotations

import os

# one thread for every BLAS/OpenMP flavour, before numpy is imported
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
             "VECLIB_MAXIMUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402

try:
    import resource  # noqa: E402
except ImportError:  # not on Windows
    resource = None
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

import osmobulge.modeling._shooting as shooting  # noqa: E402
import osmobulge.modeling.bulge as bulge  # noqa: E402
import osmobulge.modeling.table as table  # noqa: E402
from osmobulge.modeling import bulge_mechanics, mechanics_table  # noqa: E402
from osmobulge.modeling.materials import PDMS  # noqa: E402

VTILDE = np.linspace(0.005, 7.0, 200)
TARGET_SCRATCH_S = 1.0
TARGET_CACHE_S = 10e-3


def pin_to_one_core() -> str:
    """Restrict the process to one CPU of its current affinity set; describe what was done."""
    if not hasattr(os, "sched_setaffinity"):
        return "affinity not supported on this OS (threads limited to 1)"
    cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpus[-1]})
    return f"pinned to CPU {cpus[-1]} of {cpus}"


class ShootCounter:
    """Count calls (passes) and integrated rows of ``_shooting.shoot`` while active."""

    def __init__(self):
        self.calls = 0
        self.rows = 0
        self._orig = shooting.shoot

    def __enter__(self):
        def counted(material, lam0, *args, **kwargs):
            self.calls += 1
            self.rows += np.atleast_1d(lam0).size
            return self._orig(material, lam0, *args, **kwargs)

        shooting.shoot = counted
        return self

    def __exit__(self, *exc):
        shooting.shoot = self._orig
        return False


MEMO_MODULES = (bulge, shooting, table)


def clear_memo() -> int:
    """Forget every in-process memo so that a run really starts from scratch.

    Clears every ``functools.lru_cache`` function and every module-level ``*_CACHE``
    dict of the solver modules; returns how many were cleared (reported, so that a
    new memo added to the solver cannot silently make "scratch" warm).
    """
    n = 0
    for module in MEMO_MODULES:
        for name, obj in vars(module).items():
            if callable(getattr(obj, "cache_clear", None)):
                obj.cache_clear()
                n += 1
            elif name.endswith("_CACHE") and isinstance(obj, dict):
                obj.clear()
                n += 1
    return n


def build_mechanics():
    clear_memo()
    return bulge_mechanics(PDMS, VTILDE)


def build_mechanics_warm():
    return bulge_mechanics(PDMS, VTILDE)


def build_table_scratch():
    clear_memo()
    return mechanics_table(PDMS, vtilde_max=7.0, n=200, cache=False)


def load_table_cached():
    return mechanics_table(PDMS, vtilde_max=7.0, n=200)


def measure(fn, repeat: int):
    """Median and all wall times of ``repeat`` runs, shooting counts of one run, peak heap."""
    with ShootCounter() as counter:
        fn()  # warm-up (imports, first-touch) and shooting counts
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return statistics.median(times), times, counter, peak


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (median reported)")
    args = parser.parse_args(argv)

    pinning = pin_to_one_core()
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with tempfile.TemporaryDirectory(prefix="osmobulge-bench-") as tmp:
        os.environ["OSMOBULGE_CACHE_DIR"] = tmp
        # populate the cache for the cached case
        mechanics_table(PDMS, vtilde_max=7.0, n=200)
        cases = [
            ("bulge_mechanics(PDMS, linspace(0.005, 7, 200)), scratch", build_mechanics, TARGET_SCRATCH_S),
            ("bulge_mechanics(...), same, in-process memos warm", build_mechanics_warm, TARGET_SCRATCH_S),
            ("mechanics_table(PDMS, vtilde_max=7, n=200, cache=False)", build_table_scratch, TARGET_SCRATCH_S),
            ("mechanics_table(PDMS, vtilde_max=7, n=200), disk cache", load_table_cached, TARGET_CACHE_S),
        ]
        rows = []
        for name, fn, target in cases:
            med, times, counter, peak = measure(fn, args.repeat)
            rows.append((name, med, min(times), max(times), target, med / target, peak, counter.calls, counter.rows))

    load_after = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 if resource else float("nan")
    print(f"osmobulge mechanics benchmark: {platform.python_implementation()} {platform.python_version()}, "
          f"numpy {np.__version__}, {platform.machine()}; {pinning}; BLAS/OMP threads = 1; "
          f"scratch runs clear {clear_memo()} in-process memos")
    print(f"1-min load average before/after: {load_before:.2f}/{load_after:.2f} (2 cores shared); "
          f"median of {args.repeat} runs; process peak RSS {rss_mb:.0f} MB (interpreter + imports)")
    header = (f"{'case':<58} {'median':>10} {'min':>10} {'max':>10} {'target':>8} {'ratio':>6} "
              f"{'peak MB':>8} {'shoots':>6} {'rows':>7}")
    print(header)
    print("-" * len(header))
    for name, med, lo, hi, target, ratio, peak, calls, nrows in rows:
        print(f"{name:<58} {_fmt(med):>10} {_fmt(lo):>10} {_fmt(hi):>10} {_fmt(target):>8} {ratio:>6.2f} "
              f"{peak / 2**20:>8.2f} {calls:>6d} {nrows:>7d}")
    print("ratio = median / target (< 1 meets the target); shoots = calls of _shooting.shoot per build, "
          "rows = pole stretches integrated per build")


def _fmt(seconds: float) -> str:
    return f"{seconds * 1e3:.2f} ms" if seconds < 1 else f"{seconds:.3f} s"


if __name__ == "__main__":
    main()
