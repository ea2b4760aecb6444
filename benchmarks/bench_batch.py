"""Jobs per minute of ``agvdyn batch`` (agvdyn.batch.run_batch) on a LocalCluster of 1 and 2 workers.

    .venv/bin/python benchmarks/bench_batch.py [--jobs 8]

Each job identifies one simulated identification log (about 42,000 rows, default estimator and
uncertainty). The wall time includes starting the local cluster and the workers' imports, as a user sees it.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=8)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()

    from agvdyn.batch import BatchJob, run_batch
    from agvdyn.simulation import simulate

    with tempfile.TemporaryDirectory() as tmp:
        jobs = []
        for i in range(args.jobs):
            path = simulate("identification", seed=100 + i).write(Path(tmp) / f"agv{i}.parquet")
            jobs.append(BatchJob(name=f"agv{i}", logs=(str(path),)))
        for workers in args.workers:
            t0 = time.perf_counter()
            table = run_batch(jobs, workers=workers)
            wall = time.perf_counter() - t0
            failed = int((table.groupby("job")["error"].first() != "").sum())
            per_job = table.groupby("job")["seconds"].first().mean()
            print(f"{workers} worker(s): {args.jobs} jobs in {wall:.1f} s = {60 * args.jobs / wall:.1f} jobs/min "
                  f"(mean {per_job:.2f} s inside a job; {failed} failed)")


if __name__ == "__main__":
    main()
