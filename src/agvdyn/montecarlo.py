"""Monte Carlo study of estimators (``agvdyn montecarlo``): simulate -> identify N times with
different noise seeds, compare estimates and reported uncertainty with the simulated truth.

Each run is a pure function of its inputs (:func:`run_study_case`), so a pool of processes (or
a cluster) can run them. The table has one row per run, estimator, uncertainty method and
parameter; :func:`summarize` gives bias, RMSE, mean reported std, RMSE / mean std, 95 %
interval coverage and time per estimator and parameter.
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["StudyCase", "run_study_case", "run_study", "summarize", "TABLE_COLUMNS"]

#: Columns of the study table (a contract: add, don't rename).
TABLE_COLUMNS = ("run", "estimator", "uncertainty", "parameter", "value", "std", "ci_low", "ci_high", "truth",
                 "seconds", "std_classic", "seed", "error")


@dataclass(frozen=True)
class StudyCase:
    """One run: experiment, seed, simulation settings (a dict, see ``simulation.settings_from_dict``),
    platform and true parameters (dicts), and the (estimator, uncertainty) pairs to identify with."""

    run: int
    seed: int
    experiment: str
    settings: dict[str, Any]
    ideal_plant: bool
    methods: tuple[tuple[str, str], ...]
    platform: dict[str, Any] | None = None
    parameters: dict[str, float] | None = None
    options: dict[str, Any] | None = None  # further IdentificationSettings keywords


#: Tyre stiffening of the ideal plant: creep (force / slip stiffness) a hundred times below the
#: default tyres', so that the rolling constraints of the model hold to about 1e-4.
RIGID_TYRES = 100.0


def model_plant(plant: Any) -> Any:
    """The plant equal to the identification model: neglected effects off and tyres stiff enough that
    the rolling constraints hold (the default tyres creep by 0.5 % under the identification's forces,
    which biases the wheel friction by 0.1-0.2 %)."""
    return replace(plant.ideal(), slip_stiffness_long=RIGID_TYRES * plant.slip_stiffness_long,
                   slip_stiffness_lat=RIGID_TYRES * plant.slip_stiffness_lat)


def run_study_case(case: StudyCase) -> list[dict[str, Any]]:
    """Simulate one run and identify it with every method; rows of the study table."""
    from agvdyn.identification import IdentificationSettings, identify
    from agvdyn.io import Log
    from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Geometry, Parameters
    from agvdyn.simulation import settings_from_dict, simulate

    sim_settings = settings_from_dict(case.settings, "montecarlo settings")
    if case.ideal_plant:
        sim_settings = replace(sim_settings, plant=model_plant(sim_settings.plant))
    geometry = PROTOTYPE if case.platform is None else Geometry(**case.platform)
    truth = PAPER_PARAMETERS if case.parameters is None else Parameters(**case.parameters)
    result = simulate(case.experiment, platform=geometry, plant_params=truth, settings=sim_settings, seed=case.seed)
    log = Log.from_frame(result.log_frame(), sidecar=result.sidecar())
    rows = []
    for estimator, uncertainty in case.methods:
        t0 = time.perf_counter()
        error = ""
        try:
            ident = identify(log, geometry, settings=IdentificationSettings.from_flat(
                estimator=estimator, uncertainty=uncertainty, **(case.options or {})), keep_blocks=False, workers=1)
        except ValueError as exc:
            ident, error = None, str(exc).splitlines()[0]
        seconds = time.perf_counter() - t0
        for name in PARAMETER_NAMES:
            if ident is not None and name not in ident.std:
                continue
            value = math.nan if ident is None else getattr(ident.parameters, name)
            std = math.nan if ident is None else ident.std[name]
            low, high = (math.nan, math.nan) if ident is None else ident.ci95(name)
            rows.append({"run": case.run, "estimator": estimator, "uncertainty": uncertainty, "parameter": name,
                         "value": value, "std": std, "ci_low": low, "ci_high": high, "truth": getattr(truth, name), "seconds": seconds,
                         "std_classic": math.nan if ident is None else ident.std_classic.get(name, math.nan),
                         "seed": case.seed, "error": error})
    return rows


def run_study(cases: Sequence[StudyCase], *, workers: int = 1,
              progress: Callable[[int, int], None] | None = None, scheduler: str | None = None) -> pd.DataFrame:
    """Run the cases (in ``workers`` processes when > 1, or on the workers of the Dask scheduler at the
    address ``scheduler``) and return the study table."""
    rows: list[dict[str, Any]] = []
    done = 0
    if scheduler is not None:
        from agvdyn.batch import map_on_dask

        for _, result, error in map_on_dask(run_study_case, cases, scheduler=scheduler, progress=progress):
            if error is not None:
                raise error
            rows += result
    elif workers <= 1:
        for case in cases:
            rows += run_study_case(case)
            done += 1
            if progress:
                progress(done, len(cases))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for future in as_completed([pool.submit(run_study_case, c) for c in cases]):
                rows += future.result()
                done += 1
                if progress:
                    progress(done, len(cases))
    frame = pd.DataFrame(rows, columns=list(TABLE_COLUMNS))
    return frame.sort_values(["estimator", "uncertainty", "run", "parameter"], kind="stable").reset_index(drop=True)


def summarize(table: pd.DataFrame) -> pd.DataFrame:
    """Per estimator, uncertainty method and parameter: runs, failures, bias, RMSE, mean std,
    RMSE / mean std, 95 % coverage (share of runs whose interval holds the truth) with its Wilson
    95 % interval (``coverage_low``, ``coverage_high``: what the number of runs can tell), mean seconds."""
    from scipy.stats import binomtest

    def one(g: pd.DataFrame) -> pd.Series:
        ok = g[g["error"] == ""]
        err = ok["value"] - ok["truth"]
        rmse = float(np.sqrt(np.mean(err**2))) if len(ok) else math.nan
        mean_std = float(ok["std"].mean()) if len(ok) else math.nan
        covered = (ok["ci_low"] <= ok["truth"]) & (ok["truth"] <= ok["ci_high"])
        band = binomtest(int(covered.sum()), len(ok)).proportion_ci(method="wilson") if len(ok) else None
        return pd.Series({
            "runs": len(g), "failed": int((g["error"] != "").sum()),
            "bias_pct": 100 * float(err.mean() / ok["truth"].mean()) if len(ok) else math.nan,
            "rmse_pct": 100 * rmse / float(ok["truth"].abs().mean()) if len(ok) else math.nan,
            "mean_std_pct": 100 * mean_std / float(ok["truth"].abs().mean()) if len(ok) else math.nan,
            "rmse_over_std": rmse / mean_std if mean_std > 0 else math.nan,
            "coverage": float(covered.mean()) if len(ok) else math.nan,
            "coverage_low": band.low if band else math.nan, "coverage_high": band.high if band else math.nan,
            "seconds": float(g["seconds"].mean()),
        })

    return table.groupby(["estimator", "uncertainty", "parameter"], sort=False).apply(one, include_groups=False)


def default_workers() -> int:
    return max(1, min(4, os.cpu_count() or 1))
