"""Benchmark: the identification sequence (117.6 s) on the MuJoCo plant, in-process and end to end.

    .venv/bin/python benchmarks/bench_mujoco.py [--repeat 3] [--cli-repeat 2]

Prints the real-time factor (simulated seconds per wall-clock second) of ``simulate("identification",
engine="mujoco")`` in-process (after a first call that compiles or loads the per-sample kernel), and
of ``agvdyn simulate identification --engine mujoco --out TMP`` in a fresh process (start-up,
imports, MJCF generation, plan, simulation, writing the log, its sidecar and the MJCF). Target:
>= 20x end to end (issue 29). MuJoCo is stepped from Python once per 2 ms sample (two 1 ms steps);
the sensors, controller and drive of the sample are one compiled call.
"""
from __future__ import annotations

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from agvdyn.simulation import simulate  # noqa: E402
from agvdyn.trajectories import identification_sequence  # noqa: E402

TARGET = 20.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cli-repeat", type=int, default=2)
    args = parser.parse_args()
    seq = identification_sequence()
    duration = seq.duration
    simulate(seq, seed=1, engine="mujoco")  # compile / load the kernels
    best = float("inf")
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        simulate(seq, seed=1, engine="mujoco")
        best = min(best, time.perf_counter() - t0)
    print(f"in-process: {best:.2f} s for {duration:.1f} s of motion: {duration / best:.1f}x real time")
    exe = Path(sys.executable).with_name("agvdyn")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-c", "from agvdyn.cli import main; main()"]
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.cli_repeat):
            t0 = time.perf_counter()
            subprocess.run([*cmd, "simulate", "identification", "--engine", "mujoco", "--quiet",
                            "--out", str(Path(tmp) / "id.parquet")], check=True, capture_output=True)
            best = min(best, time.perf_counter() - t0)
    factor = duration / best
    print(f"end to end (agvdyn simulate identification --engine mujoco): {best:.2f} s: {factor:.1f}x real time "
          f"(target >= {TARGET:g}x: {'met' if factor >= TARGET else 'NOT met'})")


if __name__ == "__main__":
    main()
