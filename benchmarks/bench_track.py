"""Benchmark: replay rate of the online payload tracker (issue 31), samples per second on one core.

    .venv/bin/python benchmarks/bench_track.py [--duration 300] [--repeat 5]

Simulates a ``driving`` shift of ``duration`` s with a payload pick-up at mid-time (once, outside
the timing), then times :func:`agvdyn.online.track` on it (after a first call that compiles the
kernel or loads it from numba's cache): the causal row pass (filters, odometry, projection,
vectorised) and the compiled per-sample update separately and together. Prints samples/s; the
per-sample loop must run >= 50 k samples/s (issue 31).
"""
from __future__ import annotations

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from agvdyn.io import load_log  # noqa: E402
from agvdyn.online import TrackerSettings, track  # noqa: E402
from agvdyn.online.rows import causal_rows  # noqa: E402
from agvdyn.online.tracker import TrackerState, run_tracker  # noqa: E402
from agvdyn.platform import PAPER_PARAMETERS as P, PROTOTYPE  # noqa: E402
from agvdyn.simulation import SimulationSettings, simulate  # noqa: E402
from agvdyn.simulation.payload import PayloadEvent  # noqa: E402
from agvdyn.trajectories import experiment  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    traj = experiment("driving", duration=args.duration, seed=1)
    settings = SimulationSettings(payload=(PayloadEvent(traj.duration / 2, 300.0, 0.0, 0.0, 52.0),))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "drive.parquet"
        simulate(traj, settings=settings, seed=1).write(path)
        log = load_log(path)
    n = log.t.size
    track([log], PROTOTYPE, P)  # compile or load the kernel
    st = TrackerSettings()
    nominal = np.array([P.m_ch, P.C_ch])
    t_rows, t_loop, t_all = [], [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        rows = causal_rows(log.t, log.alpha, log.beta, log.torque, PROTOTYPE, P, torque_lead=0.5)
        t1 = time.perf_counter()
        run_tracker(rows, TrackerState.initial(P, {}, st), st, nominal)
        t2 = time.perf_counter()
        track([log], PROTOTYPE, P)
        t3 = time.perf_counter()
        t_rows.append(t1 - t0), t_loop.append(t2 - t1), t_all.append(t3 - t2)
    for name, times in (("rows (vectorised)", t_rows), ("update loop (compiled)", t_loop), ("track() total", t_all)):
        best = min(times)
        print(f"{name:24s} {best * 1e3:8.1f} ms  {n / best:12,.0f} samples/s")
    print(f"{n:,} samples ({n * 2e-3:.0f} s of driving); goal: update loop >= 50,000 samples/s")


if __name__ == "__main__":
    main()
