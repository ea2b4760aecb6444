"""Benchmark: planning the identification sequence (``agvdyn plan``) on two cores.

Plans the prototype's sequence in the default sequence's floor (5.2 m x 1.6 m) and in 3 m x 2 m
with the default settings (six starts of L-BFGS-B in two processes) and prints the wall-clock
time of each, the time per start and the predicted cond next to the default sequence's. Target:
under a minute per plan.
"""
from __future__ import annotations

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import time  # noqa: E402

from agvdyn.platform import PROTOTYPE  # noqa: E402
from agvdyn.trajectories.planner import PlanSettings, plan  # noqa: E402

TARGET = 60.0


def main() -> None:
    settings = PlanSettings()
    worst = 0.0
    for floor in ("5.2x1.6", "3x2"):
        t0 = time.perf_counter()
        result = plan(PROTOTYPE, floor, settings=settings)
        wall = time.perf_counter() - t0
        worst = max(worst, wall)
        per_start = [s["seconds"] for s in result.starts]
        print(f"plan {floor}: {wall:.1f} s wall on {settings.workers or min(2, os.cpu_count() or 1)} processes "
              f"({len(per_start)} starts, {min(per_start):.1f}-{max(per_start):.1f} s each), predicted cond "
              f"{result.evaluation.cond:.2f} (default sequence in the same floor {result.reference.cond:.2f}), "
              f"floor used {result.evaluation.floor.length:.2f} m x {result.evaluation.floor.width:.2f} m "
              f"(target < {TARGET:.0f} s)")
    if worst > TARGET:
        raise SystemExit(f"planning took {worst:.1f} s, above the target {TARGET:.0f} s")


if __name__ == "__main__":
    main()
