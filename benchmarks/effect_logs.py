"""Logs of the identification experiment with the effects beyond the paper's model (issue 30).

For a seed, simulates the ``identification`` experiment on our plant (default settings: stiction,
steering-unit masses, torque limit, wheel radius errors, sensor noise) once per case and writes
``<out>/seed<S>_<case>.parquet`` with its sidecar (truth in ``true_parameters`` and ``true_model``):

* ``none``: no effect (the reference for the paper model's tolerances and for ``--model auto``);
* ``breakaway``: static friction 1.3 x the sliding d_c, Stribeck velocity 0.05 rad/s, in all three
  joint groups (``agvdyn simulate --breakaway all=1.3:0.05``);
* ``delay``: the torque columns lag the angles by 6 ms = 3 samples (``--torque-delay 0.006``);
* ``payload``: 150 kg at (0.15, -0.1) m in the chassis frame from t = 0, yaw inertia 12.5 kg m^2
  about its own centre (a 0.8 x 0.6 m box; ``--payload 0:150:0.15,-0.1:12.5``): the chassis centre
  of mass at (x_c, y_c) = (22.7, -15.1) mm;
* ``all``: the three together.

Run: ``.venv/bin/python benchmarks/effect_logs.py --out DIR --seeds 1 2 3 [--cases delay all]``;
or from Python ``write_effect_logs(seed, out_dir)`` (the acceptance study, 10 seeds). Prints one
line per log with its wall time.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from agvdyn.simulation import SimulationSettings, simulate
from agvdyn.simulation.payload import PayloadEvent

EXPERIMENT = "identification"
BREAKAWAY_RATIO, STRIBECK_VELOCITY = 1.3, 0.05
TORQUE_DELAY = 0.006
PAYLOAD = PayloadEvent(t=0.0, mass=150.0, x=0.15, y=-0.1, inertia=12.5)
CASES = ("none", "breakaway", "delay", "payload", "all")


def effect_settings(case: str, base: SimulationSettings = SimulationSettings()) -> SimulationSettings:
    """The simulation settings of ``case`` (one of :data:`CASES`) on top of ``base``."""
    if case not in CASES:
        raise ValueError(f"case {case!r}: expected one of {list(CASES)}")
    settings = base
    if case in ("breakaway", "all"):
        settings = replace(settings, plant=settings.plant.with_breakaway("all", BREAKAWAY_RATIO, STRIBECK_VELOCITY))
    if case in ("delay", "all"):
        settings = replace(settings, sensors=replace(settings.sensors, torque_delay=TORQUE_DELAY))
    if case in ("payload", "all"):
        settings = replace(settings, payload=(PAYLOAD,))
    return settings


def write_effect_logs(seed: int, out_dir: str | Path, cases: tuple[str, ...] = CASES,
                      experiment: str = EXPERIMENT) -> dict[str, Path]:
    """Simulate ``experiment`` with sensor-noise seed ``seed`` once per case and write the logs
    ``out_dir/seed<seed>_<case>.parquet`` (+ sidecars); returns {case: path}."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    for case in cases:
        t0 = time.perf_counter()
        result = simulate(experiment, settings=effect_settings(case), seed=seed)
        paths[case] = result.write(out_dir / f"seed{seed}_{case}.parquet")
        print(f"seed {seed} {case:9s}: {paths[case]} ({result.trajectory.n_samples:,} samples, "
              f"{time.perf_counter() - t0:.2f} s)", flush=True)
    return paths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder of the logs")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1], help="sensor-noise seeds")
    ap.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES), help="effects to simulate")
    ap.add_argument("--experiment", default=EXPERIMENT, help="experiment name (agvdyn simulate --help)")
    args = ap.parse_args()
    for seed in args.seeds:
        write_effect_logs(seed, args.out, tuple(args.cases), args.experiment)


if __name__ == "__main__":
    main()
