"""Benchmark: planning the identification sequence (``agvdyn plan``) on two cores.

Plans the prototype's sequence (``--small``: the smaller platform of docs/planning.md, l=0.8, b=0.55,
a=0.04, r=0.075, i_G=20) in the default sequence's floor (5.2 m x 1.6 m) and in 3 m x 2 m with the
defaults of ``agvdyn plan`` (the ``--search`` of the optimiser in two processes, then the check on the
simulator of ``--verify``: the best starts and the default sequence simulated and identified on four
noise seeds, in two processes) and prints the wall-clock time of each (optimisation and check), the
time per start and the predicted and measured cond next to the default sequence's. Target: under a
minute per plan, check included.

    python benchmarks/bench_plan.py [--search narrow|wide] [--small]
"""
from __future__ import annotations

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

from agvdyn.cli.plan_commands import (  # noqa: E402
    SEARCH_DEFAULT, VERIFY_CANDIDATES, VERIFY_DEFAULT, VERIFY_PLANT_SEEDS, VERIFY_PLANTS,
)
from agvdyn.plan_check import verify_plan  # noqa: E402
from agvdyn.platform import PROTOTYPE, Geometry  # noqa: E402
from agvdyn.trajectories.planner import PlanSettings, plan  # noqa: E402

TARGET = 60.0
SMALL = Geometry(l=0.8, b=0.55, a=0.04, r=0.075, i_G=20.0, name="small")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--search", default=SEARCH_DEFAULT)
    parser.add_argument("--small", action="store_true")
    args = parser.parse_args()
    geom = SMALL if args.small else PROTOTYPE
    settings = PlanSettings.search(args.search)
    settings = PlanSettings.search(args.search, candidates=min(settings.starts, VERIFY_CANDIDATES)
                                   if VERIFY_DEFAULT > 0 else 1)  # as agvdyn plan
    workers = min(2, os.cpu_count() or 1)
    worst = 0.0
    for floor in ("5.2x1.6", "3x2"):
        t0 = time.perf_counter()
        result = plan(geom, floor, settings=settings)
        t_plan = time.perf_counter() - t0
        measured = ""
        if VERIFY_DEFAULT > 0:
            result, verification = verify_plan(result, VERIFY_DEFAULT, plants=VERIFY_PLANTS,
                                               plant_seeds=VERIFY_PLANT_SEEDS, workers=workers)
            chosen = verification.chosen_check
            measured = (f"; check on the simulator {verification.elapsed:.1f} s ({len(verification.candidates)} "
                        f"candidates x {len(verification.seeds)} seeds"
                        + (f" + {', '.join(verification.plants)}" if verification.plants else "")
                        + f"): chosen start {chosen.start}, measured cond "
                        f"{chosen.cond:.2f}, worst std ratio {chosen.ratio[chosen.worst]:.2f} ({chosen.worst})")
        wall = time.perf_counter() - t0
        worst = max(worst, wall)
        per_start = [s["seconds"] for s in result.starts]
        print(f"{geom.name} plan {floor} ({args.search}): {wall:.1f} s wall (optimisation {t_plan:.1f} s) on "
              f"{settings.workers or workers} processes "
              f"({len(per_start)} starts, {min(per_start):.1f}-{max(per_start):.1f} s each), predicted cond "
              f"{result.evaluation.cond:.2f} (default sequence in the same floor {result.reference.cond:.2f}), "
              f"floor used {result.evaluation.floor.length:.2f} m x {result.evaluation.floor.width:.2f} m "
              f"{measured} (target < {TARGET:.0f} s)", flush=True)
    if worst > TARGET:
        raise SystemExit(f"planning took {worst:.1f} s, above the target {TARGET:.0f} s")


if __name__ == "__main__":
    main()
