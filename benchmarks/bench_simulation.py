"""Benchmark: closed-loop simulation of the whole identification sequence on one core.

Prints the real-time factor (simulated seconds per wall-clock second) with default settings and
with the wheel-slip scenario of ``agvdyn simulate --slip`` (floor patches checked at every plant
substep); the target is >= 100 for both. The first call compiles (or loads from numba's cache) the
kernels and is not timed.
"""
from __future__ import annotations

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import time  # noqa: E402
from dataclasses import replace  # noqa: E402

from agvdyn.simulation import SLIP_SCENARIO, SimulationSettings, simulate  # noqa: E402
from agvdyn.trajectories import identification_sequence, lane_change  # noqa: E402

TARGET = 100.0


def main() -> None:
    t0 = time.perf_counter()
    simulate(lane_change(length=3.0, offset=0.5, straight_before=0.1, straight_after=0.1))  # compile / load cache
    warm = time.perf_counter() - t0
    traj = identification_sequence()
    print(f"identification sequence: {traj.duration:.1f} s of motion, {traj.n_samples} samples at 2 ms, "
          f"{SimulationSettings().plant.substeps} plant substeps per sample")
    print(f"first call (compile or cache load): {warm:.2f} s")
    worst = float("inf")
    for label, settings in (("default", SimulationSettings()),
                            ("--slip", replace(SimulationSettings(), slip=SLIP_SCENARIO))):
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            simulate(traj, settings=settings, seed=0)
            best = min(best, time.perf_counter() - t0)
        rtf = traj.duration / best
        worst = min(worst, rtf)
        print(f"simulate() {label}: {best:.3f} s wall (best of 3), real-time factor {rtf:.0f}x "
              f"(target >= {TARGET:.0f}x)")
    if worst < TARGET:
        raise SystemExit(f"real-time factor {worst:.0f} below the target {TARGET:.0f}")


if __name__ == "__main__":
    main()
