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

``plants`` adds plant variants (:data:`PLANT_VARIANTS`: softer or stiffer tyres, other wheel radii,
breakaway friction) as a proxy for another engine's contact: each candidate and the default sequence
are simulated on them too and a candidate's score is that of all its runs together (std ratios to the
default sequence on the same plant and seed, averaged over the nominal and the variants' runs). Measured
on both vehicles (docs/planning.md, "Stop 22, second helper"), the worst score over the plants chose
worse plans on held-out seeds and plants (a variant's score on two to four seeds scatters more than the
candidates differ), the pooled one the same plans as the nominal check but one (better); it is opt-in
(``agvdyn plan --verify-plants soft,stiff``) and reports each plant's figures. The runs can go to worker processes (``workers``; ``agvdyn plan``: two).

``engine="mujoco"`` (``agvdyn plan --verify-engine mujoco``) simulates the candidates and the default
sequence on the MuJoCo plant (:mod:`agvdyn.simulation.mujoco_plant`, generated from the plan's platform and
nominal parameters) instead of ours: the check on a second, independent engine (issue 29; the plant
variants are our plant's and are refused with it).

This is the validation stage: it imports the simulation and the identification, which the
planner (a trajectories module) must not.
"""
from __future__ import annotations

import math
import multiprocessing as mp
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from agvdyn.identification import Identification, identify
from agvdyn.io import Log
from agvdyn.simulation import ENGINES, PlantSettings, SimulationSettings, simulate
from agvdyn.trajectories.planner import FREE, Plan
from agvdyn.trajectories.planner.optimize import one_blas_thread
from agvdyn.trajectories.planner.result import COND_BAR, COND_SHARE

__all__ = ["CandidateCheck", "Verification", "verify_plan", "measured_score", "choose", "VERIFY_SEED0",
           "PREFER_PREDICTED", "PLANT_VARIANTS", "plant_variant"]

#: First noise seed of the verification runs (seeds ``VERIFY_SEED0 ... + n - 1``): apart from the
#: seeds a user simulates by default (0) and from those the acceptance is measured on (0-8).
VERIFY_SEED0 = 100
#: How much smaller another candidate's measured score must be than that of the start with the best
#: predicted objective to replace it (docs/planning.md, "Stop 22": with 0 a tie on four seeds, 1.02
#: against 1.01, chose a plan with C_r -5.2 % instead of -2.6 % on other seeds).
PREFER_PREDICTED = 0.05
#: Relative tolerance of a parameter's error (issue 11: within 5 % or 3 std of the truth).
ERROR_TOLERANCE = 0.05
#: Name of the plant of the settings as given.
NOMINAL = "nominal"
#: Plant variants of the check (``verify_plan(plants=...)``, ``agvdyn plan --verify-plants``), a proxy for
#: another engine's contact: a value, or a function of the plant's own. ``soft``/``stiff``: tyre slip
#: stiffness (longitudinal x0.625 / x4, lateral x2/3 / x4; the default plant's 4e4 / 3e4 N become
#: 2.5e4 / 2e4 and 1.6e5 / 1.2e5) and friction coefficient (x0.875 / x1.25: 0.7 / 1.0);
#: ``radii``: other wheel-radius errors; ``breakaway``: static friction 1.3x the sliding one.
PLANT_VARIANTS: dict[str, dict[str, Any]] = {
    "soft": {"slip_stiffness_long": lambda v: 0.625 * v, "slip_stiffness_lat": lambda v: v * 2 / 3,
             "mu": lambda v: 0.875 * v},
    "stiff": {"slip_stiffness_long": lambda v: 4 * v, "slip_stiffness_lat": lambda v: 4 * v, "mu": lambda v: 1.25 * v},
    "radii": {"wheel_radius_error": (-0.003, 0.002, 0.0025, -0.001)},
    "breakaway": {"breakaway_ratio": 1.3, "stribeck_velocity": 0.02},
}


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
    plants: dict[str, dict[str, Any]] = field(default_factory=dict)
    search: str = ""

    @property
    def worst(self) -> str:
        """The parameter with the largest mean std ratio."""
        return max(self.ratio, key=self.ratio.get) if self.ratio else ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; what could not be measured (a failure) is null."""
        return {"rank": self.rank, "start": self.start, "search": self.search or None,
                "objective_value": _num(self.objective_value),
                "predicted": {"cond": _num(self.predicted_cond), "ratio": _nums(self.predicted_ratio),
                              "worst_ratio": _num(max(self.predicted_ratio.values()))},
                "measured": {"cond": _num(self.cond), "ratio": _nums(self.ratio), "ratio_max": _nums(self.ratio_max),
                             "worst": self.worst or None, "worst_ratio": _num(self.ratio.get(self.worst, math.inf)),
                             "error_percent": _nums(self.error),
                             "max_error_percent": _num(max(self.error.values(), default=math.inf)),
                             "error_share": _num(self.error_share)},
                "score": _num(self.score), "failure": self.failure,
                "plants": {p: {"score": _num(m["score"]), "cond": _num(m["cond"]), "default_cond": m["default_cond"],
                               "ratio": _nums(m["ratio"]), "max_error_percent": _num(max(m["error"].values())),
                               "error_share": _num(m["error_share"])} for p, m in self.plants.items()}}


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
    plants: tuple[str, ...] = ()
    plant_seeds: tuple[int, ...] = ()
    engine: str = "ours"

    @property
    def chosen_check(self) -> CandidateCheck:
        return next(c for c in self.candidates if c.rank == self.chosen)

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the chosen candidate misses on the simulator (mean cond above the bar, a mean std ratio
        above 1, an error beyond 5 % and 3 std on some seed)."""
        c = self.chosen_check
        where = "MuJoCo" if self.engine == "mujoco" else "the simulator"
        if c.failure is not None:
            return (f"measured on {where}: every candidate failed ({c.failure})",)
        out, bar = [], _cond_bar(self.default_cond)
        if c.cond > bar:
            on = f"seed {self.seeds[0]}" if len(self.seeds) == 1 else f"seeds {self.seeds[0]}-{self.seeds[-1]}"
            out.append(f"measured on {where} ({on}): cond {c.cond:.2f} above "
                       f"{bar:.2f} (9, or 0.6x the default sequence's {self.default_cond:.2f})")
        worse = {n: r for n, r in c.ratio.items() if r > 1}
        if worse:
            out.append(f"measured on {where}: mean std above the default sequence's for "
                       + ", ".join(f"{n} ({r:.2f}x)" for n, r in worse.items()))
        if c.error_share > 1:
            n = max(c.error, key=c.error.get)
            out.append(f"measured on {where}: an error beyond 5 % and 3 std (largest {n} {c.error[n]:.1f} %)")
        for p, m in c.plants.items():
            if m["score"] > 1:
                w = max(m["ratio"], key=m["ratio"].get)
                out.append(f"measured on the {p} plant variant: score {m['score']:.2f} (cond {m['cond']:.2f}, "
                           f"{w} std {m['ratio'][w]:.2f}x the default's, largest error {max(m['error'].values()):.1f} %)")
        if out:
            out.append("plan again with another --seed, --search narrow,wide, more --starts, or a longer --duration")
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        chosen = self.chosen_check
        return {"seeds": list(self.seeds), "chosen_rank": self.chosen, "chosen_start": chosen.start, "chosen_search": chosen.search or None,
                "score": _num(chosen.score), "cond_bar": _cond_bar(self.default_cond), "warnings": list(self.warnings),
                "default": {"cond": self.default_cond, "std": dict(self.default_std)},
                "candidates": [c.to_dict() for c in self.candidates], "elapsed_s": self.elapsed,
                "plants": [NOMINAL, *self.plants], "plant_seeds": list(self.plant_seeds), "engine": self.engine}


def _cond_bar(default_cond: float) -> float:
    return min(COND_BAR, COND_SHARE * default_cond)


def measured_score(ratio: dict[str, float], cond: float, default_cond: float, error_share: float) -> float:
    """``max(largest mean std ratio, cond / min(9, 0.6 cond_default), error share)`` (see the module)."""
    return float(max(max(ratio.values(), default=math.inf), cond / _cond_bar(default_cond), error_share))


def plant_variant(plant: PlantSettings, name: str) -> PlantSettings:
    """``plant`` with the tyres or wheel radii of the variant ``name`` (:data:`PLANT_VARIANTS`): scaled
    tyre stiffness and friction, or other wheel-radius errors."""
    if name == NOMINAL:
        return plant
    try:
        change = PLANT_VARIANTS[name]
    except KeyError:
        raise ValueError(f"plant variant {name!r}: expected one of {[NOMINAL, *PLANT_VARIANTS]}") from None
    values = {k: (v(getattr(plant, k)) if callable(v) else v) for k, v in change.items()}
    return replace(plant, **values)


def _run(trajectory, plan: Plan, seed: int, settings: SimulationSettings, engine: str = "ours") -> Identification:
    """Simulate ``trajectory`` with the plan's nominal parameters on ``seed`` on the plant ``engine`` and
    identify it (the defaults of ``agvdyn identify``, B_w fixed at its nominal value)."""
    geom = plan.trajectory.geometry
    result = simulate(trajectory, platform=geom, plant_params=plan.params, settings=settings, seed=seed, engine=engine)
    log = Log.from_frame(result.log_frame(), sidecar=result.sidecar())
    return identify(log, geom, fixed={"B_w": plan.params.B_w}, keep_blocks=False, workers=1)


def _summary(ident) -> tuple[dict[str, float], dict[str, float], float]:
    return ({n: float(ident.std[n]) for n in FREE}, {n: float(getattr(ident.parameters, n)) for n in FREE},
            float(ident.condition_number))


#: What the worker processes of :func:`verify_plan` inherit (forked): the trajectories, the plan, the settings.
_SHARED: dict[str, Any] = {}


def _task(key):
    """One simulation and identification (in a forked worker or here): the summary, or the exception's text."""
    i, p, seed = key
    try:
        return _summary(_run(_SHARED["trajs"][i], _SHARED["plan"], seed, _SHARED["sims"][p], _SHARED["engine"]))
    except Exception as exc:  # noqa: BLE001 - reported by the caller
        return f"{type(exc).__name__}: {exc}"


def _measure(runs, default, params) -> dict[str, Any]:
    """A candidate's figures on one plant: ``runs`` and ``default`` are summaries on the same seeds."""
    ratios = np.array([[r[0][n] / d[0][n] for n in FREE] for r, d in zip(runs, default)])
    truth = np.array([getattr(params, n) for n in FREE])
    values = np.array([[r[1][n] for n in FREE] for r in runs])
    stds = np.array([[r[0][n] for n in FREE] for r in runs])
    err = np.abs(values - truth)
    share = float(np.max(err / np.maximum(ERROR_TOLERANCE * np.abs(truth), 3 * stds)))
    default_cond = float(np.mean([d[2] for d in default]))
    ratio = dict(zip(FREE, ratios.mean(0).tolist()))
    cond = float(np.mean([r[2] for r in runs]))
    return {"cond": cond, "ratio": ratio, "ratio_max": dict(zip(FREE, ratios.max(0).tolist())),
            "error": dict(zip(FREE, (100 * err.max(0) / np.abs(truth)).tolist())), "error_share": share,
            "default_cond": default_cond, "score": measured_score(ratio, cond, default_cond, share)}


def verify_plan(plan: Plan, seeds: int | tuple[int, ...] = 4, *, candidates: int | None = None,
                settings: SimulationSettings = SimulationSettings(),
                prefer_predicted: float = PREFER_PREDICTED, plants: tuple[str, ...] = (),
                plant_seeds: int | tuple[int, ...] = 2, workers: int = 1,
                engine: str = "ours") -> tuple[Plan, Verification]:
    """Simulate and identify the plan's best ``candidates`` (default: all it kept,
    ``PlanSettings.candidates``) and the default sequence in the same floor on ``seeds`` (an int n:
    seeds ``VERIFY_SEED0 ... + n - 1``); return the plan with the candidate :func:`choose` takes
    and the :class:`Verification`.

    ``plants``: names of :data:`PLANT_VARIANTS` on which every candidate and the default sequence are
    simulated too (on ``plant_seeds``, an int n: seeds ``VERIFY_SEED0 ... + n - 1``), as a proxy for
    another engine's tyres and wheels; a candidate's score is then that of all its runs pooled (each
    run's std ratios against the default sequence on the same plant and seed; the mean cond and the
    bar over all runs), and each plant's own figures are kept in :attr:`CandidateCheck.plants`.
    ``workers`` > 1: the runs in that many processes. ``engine``: the plant of every run, ``"ours"`` or
    ``"mujoco"`` (no ``plants`` with it: the variants are our plant's).

    About 0.2-0.5 s per simulation and identification on the project's machine (117.6 s at 2 ms).
    """
    t0 = time.perf_counter()
    if engine not in ENGINES:
        raise ValueError(f"verify_plan: engine={engine!r}: expected one of {ENGINES}")
    seeds = _seeds(seeds)
    if not seeds:
        raise ValueError("verify_plan: expected at least one seed")
    pool = plan.candidates[:candidates] if candidates is not None else plan.candidates
    if not pool:
        raise ValueError("verify_plan: the plan keeps no candidates (PlanSettings.candidates >= 1)")
    plants = tuple(p for p in plants if p != NOMINAL)
    if plants and engine != "ours":
        raise ValueError(f"verify_plan: plant variants {', '.join(plants)} are our plant's: expected none with "
                         f"engine={engine!r}")
    variant_seeds = _seeds(plant_seeds) if plants else ()
    if plants and not variant_seeds:
        raise ValueError("verify_plan: expected at least one seed on the plant variants")
    sims = {NOMINAL: settings, **{p: replace(settings, plant=plant_variant(settings.plant, p)) for p in plants}}
    on = {NOMINAL: seeds, **{p: variant_seeds for p in plants}}
    trajs = [plan.reference_trajectory] + [c.trajectory for c in pool]
    tasks = [(i, p, s) for p in sims for s in on[p] for i in range(len(trajs))]
    forked = workers > 1 and "fork" in mp.get_all_start_methods()
    _SHARED.update(trajs=trajs, plan=plan, sims=sims, engine=engine)
    try:
        with one_blas_thread(forked):  # one BLAS thread per forked worker
            if forked:
                with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("fork")) as ex:
                    out = list(ex.map(_task, tasks))
            else:
                out = [_task(t) for t in tasks]
    finally:
        _SHARED.clear()
    results = dict(zip(tasks, out))
    for (i, p, s), r in results.items():
        if i == 0 and isinstance(r, str):
            raise RuntimeError(f"the default sequence on the {p} plant, seed {s}: {r}")
    params = plan.params
    default = {p: [results[(0, p, s)] for s in on[p]] for p in sims}
    default_cond = float(np.mean([d[2] for d in default[NOMINAL]]))
    default_std = {n: float(np.mean([d[0][n] for d in default[NOMINAL]])) for n in FREE}
    checks = []
    for j, cand in enumerate(pool, start=1):
        predicted = {n: cand.evaluation.std[n] / plan.reference.std[n] for n in FREE}
        runs = {p: [results[(j, p, s)] for s in on[p]] for p in sims}
        failed = next((r for p in sims for r in runs[p] if isinstance(r, str)), None)
        if failed is not None:
            checks.append(CandidateCheck(cand.rank, cand.start, cand.objective_value, cand.evaluation.cond, predicted,
                                         math.inf, {}, {}, {}, math.inf, math.inf, failed, search=cand.search))
            continue
        m = {p: _measure(runs[p], default[p], params) for p in sims}
        nom = m[NOMINAL]
        pooled = _measure([r for p in sims for r in runs[p]], [d for p in sims for d in default[p]], params)
        checks.append(CandidateCheck(
            cand.rank, cand.start, cand.objective_value, cand.evaluation.cond, predicted, nom["cond"], nom["ratio"],
            nom["ratio_max"], nom["error"], nom["error_share"], pooled["score"],
            plants={p: m[p] for p in plants}, search=cand.search))
    chosen = choose(checks, prefer_predicted)
    verification = Verification(seeds, tuple(checks), chosen, default_cond, default_std, time.perf_counter() - t0,
                                plants, variant_seeds, engine)
    return plan.choose(chosen), verification


def _seeds(seeds: int | tuple[int, ...]) -> tuple[int, ...]:
    return tuple(range(VERIFY_SEED0, VERIFY_SEED0 + int(seeds))) if isinstance(seeds, int) else tuple(seeds)


def choose(checks, prefer_predicted: float = PREFER_PREDICTED) -> int:
    """Rank of the candidate to keep: the one with the smallest measured score, where the start with the
    best predicted objective (the lowest rank) counts ``prefer_predicted`` less; ties to the lower rank."""
    first = min(c.rank for c in checks)
    return min(checks, key=lambda c: (c.score - (prefer_predicted if c.rank == first else 0.0), c.rank)).rank
