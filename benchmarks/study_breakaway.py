"""Breakaway friction in the identification (issue 30): the table of docs/identification.md, "Breakaway friction".

For each breakaway ratio (static / sliding friction, all three joint groups), Stribeck velocity w_s
and seed, simulates the ``identification`` experiment on our plant and fits the paper's model and the
Stribeck model at the true w_s, with the default rows and with the rows for stick-slip logs
(``filtering="matched"``, ``steering_guard=12``; for the Stribeck model also ``stiction_threshold=0.005``).
Prints per (ratio, w_s, model, rows) the mean error over the seeds and the largest |error| (%) of
C_l, C_r, d_vl, d_vr, d_cl, d_cr, d_vw, d_cw and the breakaway levels, as a markdown table.

Run: ``.venv/bin/python benchmarks/study_breakaway.py [--ratios 1.2 1.5] [--speeds 0.02 0.05 0.1]
[--seeds 0 1 2 3 4]`` (about 3 s per log and configuration on one core).
"""
from __future__ import annotations

import argparse
import math
from dataclasses import replace

import numpy as np

from agvdyn.identification import IdentificationSettings, identify
from agvdyn.io import Log
from agvdyn.model_spec import ModelSpec
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE
from agvdyn.simulation import SimulationSettings, simulate

NAMES = ("C_l", "C_r", "d_vl", "d_vr", "d_cl", "d_cr", "d_vw", "d_cw", "d_sl", "d_sr", "d_sw")
#: Settings that only report (the Stribeck fit's steering breakaway levels are no estimates: they may
#: be negative or have a std above half their value; see the docs).
REPORTING = dict(max_relative_std=math.inf, plausibility=False)
ROWS = {"default": {}, "stick-slip": dict(filtering="matched", steering_guard=12.0)}
CASES = (("paper", "default"), ("stribeck", "default"), ("paper", "stick-slip"), ("stribeck", "stick-slip"))


def breakaway_log(ratio: float, w_s: float, seed: int) -> Log:
    settings = SimulationSettings()
    settings = replace(settings, plant=settings.plant.with_breakaway("all", ratio, w_s))
    result = simulate("identification", settings=settings, seed=seed)
    return Log.from_frame(result.log_frame(), sidecar=result.sidecar())


def errors(log: Log, ratio: float, w_s: float, model: str, rows: str) -> dict[str, float]:
    """Errors (%) of one fit against the plant's truth (breakaway levels against ratio x d_c)."""
    spec = ModelSpec() if model == "paper" else ModelSpec(friction="stribeck", stribeck_velocities=(w_s,) * 3)
    flat = {**REPORTING, **ROWS[rows], **(dict(stiction_threshold=0.005) if model != "paper" and rows != "default"
                                         else {})}
    ident = identify(log, PROTOTYPE, model=spec, settings=IdentificationSettings.from_flat(**flat), keep_blocks=False)
    out = {n: 100 * (getattr(ident.parameters, n) / getattr(PAPER_PARAMETERS, n) - 1) for n in NAMES[:8]}
    for n in NAMES[8:]:
        if n in ident.extra:
            out[n] = 100 * (ident.extra[n] / (ratio * getattr(PAPER_PARAMETERS, f"d_c{n[-1]}")) - 1)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ratios", type=float, nargs="+", default=[1.2, 1.5])
    ap.add_argument("--speeds", type=float, nargs="+", default=[0.02, 0.05, 0.1])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    args = ap.parse_args()
    print("| ratio | w_s | model, rows | " + " | ".join(NAMES) + " |")
    print("|---|---|---|" + "---|" * len(NAMES))
    for ratio in args.ratios:
        for w_s in args.speeds:
            logs = [breakaway_log(ratio, w_s, seed) for seed in args.seeds]
            for model, rows in CASES:
                found = [errors(log, ratio, w_s, model, rows) for log in logs]
                cells = [f"{np.mean([f[n] for f in found]):+.1f} ({np.max([abs(f[n]) for f in found]):.1f})"
                         if n in found[0] else "" for n in NAMES]
                print(f"| {ratio:g} | {w_s:g} | {model}, {rows} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
