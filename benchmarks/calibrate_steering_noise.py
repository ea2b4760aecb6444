"""Refit the steering noise levels of ``NoiseLevels.calibrated`` (the planner's predicted stds) to the
jackknife stds of ``agvdyn identify`` on the simulator's default plant.

    .venv/bin/python benchmarks/calibrate_steering_noise.py [--seeds 0-3 ...] [--floors 5.2x1.6 3x2]

For each sequence (the default identification sequence and ``plan()``'s plan of each floor, prototype)
and seed: simulate (default plant), identify (defaults: wls, jackknife std) and predict the stds with
``evaluate_sequence``. The steering levels ``alpha_l``, ``alpha_r`` are scaled by the geometric mean of
jackknife / predicted over the parameters of their side (C, d_v, d_c; the prediction of those is
proportional to the side's level), the knees and the other levels kept. Prints predicted / jackknife
(mean over seeds) per parameter and sequence before and after, and the RMS log error over all ten.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import replace

import numpy as np

from agvdyn.identification import identify
from agvdyn.io import Log
from agvdyn.platform import PROTOTYPE
from agvdyn.simulation import simulate
from agvdyn.trajectories import planner as pl
from study_model_extensions import _seeds  # the study's --seeds (this folder is on sys.path)

SIDES = {"alpha_l": ("C_l", "d_vl", "d_cl"), "alpha_r": ("C_r", "d_vr", "d_cr")}


def _ratios(sequences, measured, noise) -> dict[str, np.ndarray]:
    settings = replace(pl.PlanSettings(), noise=noise)
    return {name: np.array([pl.evaluate_sequence(traj, settings=settings).std[n] / measured[name][n]
                            for n in pl.FREE]) for name, traj in sequences.items()}


def _show(label: str, ratios: dict[str, np.ndarray]) -> float:
    logs = np.concatenate([np.log(r) for r in ratios.values()])
    rms = float(np.sqrt(np.mean(logs ** 2)))
    print(f"{label}: RMS log(predicted / jackknife) {rms:.3f}")
    for name, r in ratios.items():
        print(f"  {name:22s} " + " ".join(f"{n} {v:.2f}" for n, v in zip(pl.FREE, r)))
    return rms


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", default=["0-3"])
    ap.add_argument("--floors", nargs="*", default=["5.2x1.6", "3x2"])
    args = ap.parse_args(argv)
    seeds = _seeds(args.seeds)
    sequences = {"default sequence": simulate("identification", seed=seeds[0]).trajectory}
    for floor in args.floors:
        sequences[f"plan {floor}"] = pl.plan(PROTOTYPE, floor).trajectory
    measured = {}
    for name, traj in sequences.items():
        runs = [identify([Log.from_frame(simulate(traj, seed=s).log_frame())], PROTOTYPE) for s in seeds]
        measured[name] = {n: float(np.mean([r.std[n] for r in runs])) for n in pl.FREE}
        print(f"identified {name} on seeds {seeds}", flush=True)
    old = pl.NoiseLevels.calibrated()
    before = _ratios(sequences, measured, old)
    _show(f"calibrated {old.alpha_l:.3f} / {old.alpha_r:.3f} N m", before)
    index = {n: i for i, n in enumerate(pl.FREE)}
    scaled = {}
    for level, names in SIDES.items():
        logs = [math.log(r[index[n]]) for r in before.values() for n in names]
        scaled[level] = getattr(old, level) * math.exp(-float(np.mean(logs)))
    new = replace(old, **scaled)
    _show(f"refitted {new.alpha_l:.3f} / {new.alpha_r:.3f} N m", _ratios(sequences, measured, new))


if __name__ == "__main__":
    main()
