"""Batch throughput: experiments per minute with 1 and 2 local worker processes.

Writes the demo campaign once (``osmobulge.experiments.demo``: the paper's five
conditions, synthetic frames), then runs process + fit + report on fresh copies
of it with ``scheduler="processes"`` and 1, then 2 workers (``force=True``, so
every step is computed), and prints a table of medians over ``--repeats`` runs and
the 2-worker / 1-worker speed-up.

    python benchmarks/batch.py [--chambers 1] [--repeats 1] [--dir /tmp/ob-batch]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chambers", type=int, default=1, help="chambers per condition (5 conditions)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--dir", type=Path, default=None)
    args = ap.parse_args()

    from osmobulge.experiments.demo import write_demo_campaign
    from osmobulge.experiments.runs import run_batch

    root = args.dir or Path(tempfile.mkdtemp(prefix="ob-batch-"))
    try:
        _run(root, args, write_demo_campaign, run_batch)
    finally:
        if args.dir is None:
            shutil.rmtree(root, ignore_errors=True)


def _run(root, args, write_demo_campaign, run_batch):
    src = root / "source"
    t0 = time.perf_counter()
    folders = write_demo_campaign(src, chambers=args.chambers, workers=2)
    print(f"wrote {len(folders)} experiments in {time.perf_counter() - t0:.1f} s ({src})")
    print(f"CPUs: {os.cpu_count()}; load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    rows = []
    for workers in (1, 2):
        times = []
        for r in range(args.repeats):
            dst = root / f"w{workers}-r{r}"
            shutil.rmtree(dst, ignore_errors=True)
            shutil.copytree(src, dst)
            dirs = [dst / f.relative_to(src) for f in folders]
            res = run_batch(dirs, ("process", "fit", "report"), scheduler="processes", workers=workers, force=True)
            if res.exit_code != 0:
                bad = [o for o in res.outcomes if o.status != "ok"]
                raise SystemExit(f"{len(bad)} experiments failed, e.g. {bad[0].path}: {bad[0].error}")
            times.append(res.seconds)
        med = statistics.median(times)
        rows.append((workers, len(folders), med, 60.0 * len(folders) / med))
    print(f"\n{'workers':>7} {'experiments':>11} {'median s':>9} {'exp/min':>8}")
    for w, n, s, rate in rows:
        print(f"{w:>7} {n:>11} {s:>9.1f} {rate:>8.2f}")
    print(f"\nspeed-up 2 vs 1 worker: {rows[1][3] / rows[0][3]:.2f}x")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (other processes share the CPUs)")


if __name__ == "__main__":  # distributed/spawn need the guard
    main()
