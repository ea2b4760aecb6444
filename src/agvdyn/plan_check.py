"""A plan checked on the simulator: each candidate start simulated and identified next to the default sequence.

The planner (:func:`agvdyn.trajectories.planner.plan`) ranks its starts by a predicted objective whose
noise model is 15-20 % off per parameter, and single plans that it rates alike differ by ~30 % on the
simulator (docs/planning.md, stops 20-21). :func:`verify_plan` simulates the best candidates
(:attr:`Plan.candidates`) with the nominal parameters on a few noise seeds, identifies each with the
defaults of ``agvdyn identify`` (``wls``, jackknife std) and does the same with the default sequence
fitted into the same floor and duration (:attr:`Plan.reference_trajectory`). It keeps the candidate
that is furthest inside the bars of issue 11, measured:

``score = max(max_i mean_s(std_i / std_i,default), cond / cond_bar, max_s,i |p_i - p_i,true| / tol_i)``

with ``cond_bar = min(9, 0.6 cond_default)`` and ``tol_i = max(5 % |p_i,true|, 3 std_i)``: every
term is at most 1 where the plan meets the bar. The start with the best predicted objective is kept
unless another one's score is smaller by more than ``prefer_predicted`` (0.05, about the scatter of a
score over four seeds); then the smallest score wins. The measured figures are reported next to the
predicted ones (``agvdyn plan --verify``). Measured on two vehicles and four plan seeds each
(docs/planning.md, "Stop 22"): with four seeds the chosen plans were never worse than the predicted
best on six other noise seeds, and better where the predicted best missed a bar by far.

This is the validation stage: it imports the simulation and the identification, which the
planner (a trajectories module) must not.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.identification import Identification, identify
from agvdyn.io import Log
from agvdyn.simulation import SimulationSettings, simulate
from agvdyn.trajectories.planner import FREE, Plan
from agvdyn.trajectories.planner.optimize import COND_BAR, COND_SHARE

__all__ = ["CandidateCheck", "Verification", "verify_plan", "measured_score", "choose", "VERIFY_SEED0",
           "PREFER_PREDICTED"]

#: First noise seed of the verification runs (seeds ``VERIFY_SEED0 ... + n - 1``): apart from the
#: seeds a user simulates by default (0) and from those the acceptance is measured on (0-8).
VERIFY_SEED0 = 100
#: How much smaller another candidate's measured score must be than that of the start with the best
#: predicted objective to replace it (docs/planning.md, "Stop 22": with 0 a tie on four seeds, 1.02
#: against 1.01, chose a plan with C_r -5.2 % instead of -2.6 % on other seeds).
PREFER_PREDICTED = 0.05
#: Relative tolerance of a parameter's error (issue 11: within 5 % or 3 std of the truth).
ERROR_TOLERANCE = 0.05


@dataclass(frozen=True)
class CandidateCheck:
    """One candidate measured on the simulator (means over the seeds unless said otherwise).

    ``ratio``: mean over the seeds of its std / the default sequence's std on the same seed, per
    parameter; ``ratio_max``: the largest over the seeds; ``error``: the largest |error| over the
    seeds, % of the truth, per parameter; ``error_share``: the largest |error| / max(5 %, 3 std);
    ``score``: see the module (at most 1: the bars are met); ``failure``: why it could not be
    measured (the identification refused it), else None."""

    rank: int
    start: int
    objective_value: float
    predicted_cond: float
    predicted_ratio: dict[str, float]
    cond: float
    ratio: dict[str, float]
    ratio_max: dict[str, float]
    error: dict[str, float]
    error_share: float
    score: float
    failure: str | None = None

    @property
    def worst(self) -> str:
        """The parameter with the largest mean std ratio."""
        return max(self.ratio, key=self.ratio.get) if self.ratio else ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; what could not be measured (a failure) is null."""
        return {"rank": self.rank, "start": self.start, "objective_value": _num(self.objective_value),
                "predicted": {"cond": _num(self.predicted_cond), "ratio": _nums(self.predicted_ratio),
                              "worst_ratio": _num(max(self.predicted_ratio.values()))},
                "measured": {"cond": _num(self.cond), "ratio": _nums(self.ratio), "ratio_max": _nums(self.ratio_max),
                             "worst": self.worst or None, "worst_ratio": _num(self.ratio.get(self.worst, math.inf)),
                             "error_percent": _nums(self.error),
                             "max_error_percent": _num(max(self.error.values(), default=math.inf)),
                             "error_share": _num(self.error_share)},
                "score": _num(self.score), "failure": self.failure}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _nums(d: dict[str, float]) -> dict[str, float | None]:
    return {k: _num(v) for k, v in d.items()}


@dataclass(frozen=True)
class Verification:
    """Result of :func:`verify_plan`: the candidates measured, which was chosen, the default sequence's
    mean cond and stds on the same seeds."""

    seeds: tuple[int, ...]
    candidates: tuple[CandidateCheck, ...]
    chosen: int
    default_cond: float
    default_std: dict[str, float]
    elapsed: float

    @property
    def chosen_check(self) -> CandidateCheck:
        return next(c for c in self.candidates if c.rank == self.chosen)

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the chosen candidate misses on the simulator (mean cond above the bar, a mean std ratio
        above 1, an error beyond 5 % and 3 std on some seed)."""
        c = self.chosen_check
        if c.failure is not None:
            return (f"measured on the simulator: every candidate failed ({c.failure})",)
        out, bar = [], _cond_bar(self.default_cond)
        if c.cond > bar:
            on = f"seed {self.seeds[0]}" if len(self.seeds) == 1 else f"seeds {self.seeds[0]}-{self.seeds[-1]}"
            out.append(f"measured on the simulator ({on}): cond {c.cond:.2f} above "
                       f"{bar:.2f} (9, or 0.6x the default sequence's {self.default_cond:.2f})")
        worse = {n: r for n, r in c.ratio.items() if r > 1}
        if worse:
            out.append("measured on the simulator: mean std above the default sequence's for "
                       + ", ".join(f"{n} ({r:.2f}x)" for n, r in worse.items()))
        if c.error_share > 1:
            n = max(c.error, key=c.error.get)
            out.append(f"measured on the simulator: an error beyond 5 % and 3 std (largest {n} {c.error[n]:.1f} %)")
        if out:
            out.append("plan again with another --seed or more --starts, or a longer --duration")
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        chosen = self.chosen_check
        return {"seeds": list(self.seeds), "chosen_rank": self.chosen, "chosen_start": chosen.start,
                "score": _num(chosen.score), "cond_bar": _cond_bar(self.default_cond), "warnings": list(self.warnings),
                "default": {"cond": self.default_cond, "std": dict(self.default_std)},
                "candidates": [c.to_dict() for c in self.candidates], "elapsed_s": self.elapsed}


def _cond_bar(default_cond: float) -> float:
    return min(COND_BAR, COND_SHARE * default_cond)


def measured_score(ratio: dict[str, float], cond: float, default_cond: float, error_share: float) -> float:
    """``max(largest mean std ratio, cond / min(9, 0.6 cond_default), error share)`` (see the module)."""
    return float(max(max(ratio.values(), default=math.inf), cond / _cond_bar(default_cond), error_share))


def _run(trajectory, plan: Plan, seed: int, settings: SimulationSettings) -> Identification:
    """Simulate ``trajectory`` with the plan's nominal parameters on ``seed`` and identify it (the defaults
    of ``agvdyn identify``, B_w fixed at its nominal value)."""
    geom = plan.trajectory.geometry
    result = simulate(trajectory, platform=geom, plant_params=plan.params, settings=settings, seed=seed)
    log = Log.from_frame(result.log_frame(), sidecar=result.sidecar())
    return identify(log, geom, fixed={"B_w": plan.params.B_w}, keep_blocks=False, workers=1)


def verify_plan(plan: Plan, seeds: int | tuple[int, ...] = 4, *, candidates: int | None = None,
                settings: SimulationSettings = SimulationSettings(),
                prefer_predicted: float = PREFER_PREDICTED) -> tuple[Plan, Verification]:
    """Simulate and identify the plan's best ``candidates`` (default: all it kept,
    ``PlanSettings.candidates``) and the default sequence in the same floor on ``seeds`` (an int n:
    seeds ``VERIFY_SEED0 ... + n - 1``); return the plan with the candidate :func:`choose` takes
    and the :class:`Verification`.

    About 0.2-0.5 s per simulation and identification on the project's machine (117.6 s at 2 ms).
    """
    t0 = time.perf_counter()
    seeds = tuple(range(VERIFY_SEED0, VERIFY_SEED0 + int(seeds))) if isinstance(seeds, int) else tuple(seeds)
    if not seeds:
        raise ValueError("verify_plan: expected at least one seed")
    pool = plan.candidates[:candidates] if candidates is not None else plan.candidates
    if not pool:
        raise ValueError("verify_plan: the plan keeps no candidates (PlanSettings.candidates >= 1)")
    params = plan.params
    default = [_run(plan.reference_trajectory, plan, s, settings) for s in seeds]
    default_cond = float(np.mean([d.condition_number for d in default]))
    default_std = {n: float(np.mean([d.std[n] for d in default])) for n in FREE}
    checks = []
    for cand in pool:
        predicted = {n: cand.evaluation.std[n] / plan.reference.std[n] for n in FREE}
        try:
            runs = [_run(cand.trajectory, plan, s, settings) for s in seeds]
        except Exception as exc:  # noqa: BLE001 - a refused identification is a measured outcome
            checks.append(CandidateCheck(cand.rank, cand.start, cand.objective_value, cand.evaluation.cond, predicted,
                                         math.inf, {}, {}, {}, math.inf, math.inf, f"{type(exc).__name__}: {exc}"))
            continue
        ratios = np.array([[r.std[n] / d.std[n] for n in FREE] for r, d in zip(runs, default)])
        truth = np.array([getattr(params, n) for n in FREE])
        values = np.array([[getattr(r.parameters, n) for n in FREE] for r in runs])
        stds = np.array([[r.std[n] for n in FREE] for r in runs])
        err = np.abs(values - truth)
        share = float(np.max(err / np.maximum(ERROR_TOLERANCE * np.abs(truth), 3 * stds)))
        ratio = dict(zip(FREE, ratios.mean(0).tolist()))
        cond = float(np.mean([r.condition_number for r in runs]))
        checks.append(CandidateCheck(
            cand.rank, cand.start, cand.objective_value, cand.evaluation.cond, predicted, cond, ratio,
            dict(zip(FREE, ratios.max(0).tolist())), dict(zip(FREE, (100 * err.max(0) / np.abs(truth)).tolist())),
            share, measured_score(ratio, cond, default_cond, share)))
    chosen = choose(checks, prefer_predicted)
    verification = Verification(seeds, tuple(checks), chosen, default_cond, default_std, time.perf_counter() - t0)
    return plan.choose(chosen), verification


def choose(checks, prefer_predicted: float = PREFER_PREDICTED) -> int:
    """Rank of the candidate to keep: the one with the smallest measured score, where the start with the
    best predicted objective (the lowest rank) counts ``prefer_predicted`` less; ties to the lower rank."""
    first = min(c.rank for c in checks)
    return min(checks, key=lambda c: (c.score - (prefer_predicted if c.rank == first else 0.0), c.rank)).rank
