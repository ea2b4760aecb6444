"""Acceptance study of the model beyond the paper (issue 30) on our plant and on the MuJoCo plant.

For each seed and case (an effect of :mod:`agvdyn.model_spec` simulated on our plant) the
identification experiment is simulated with the effect (seed S; the cases with a payload also the
``car-like`` experiment, seed 1000 + S: only car-like turns see the centre of mass' y_c), and a lane
change with the same effect (seed 2000 + S) for validation. Fitted on the identification data:

* ``paper``: :func:`agvdyn.identification.identify` (the paper's model, B_w fixed at its true value);
* ``extension``: the matching extension alone (:func:`agvdyn.identification.identify_model` with
  ``delay="auto"``, ``com_offset=True`` or ``friction="stribeck"`` searched; all three for ``all``);
* ``auto``: :func:`agvdyn.identification.compare_models` with the lane change as its validation score
  (the mean NRMSE without stiction rows, as ``agvdyn identify --validation``), on the first
  ``--compare-seeds`` seeds; its choice like with like (the default: two models compared on the
  evidence rows of their difference, the chassis rows for the delay) and, from the same scores, the
  choice on all rows (``chosen_all_rows``: the rule before, ``chosen_model(..., rows="all")``).

Recorded per fit: the error of the paper's 10 parameters against the sidecar's truth (% and in std),
the effect's recovery (delay in sample periods, y_c in cm -- x_c cancels in every motion mode and is
held at 0 with an infinite std --, the breakaway levels d_s in %), auto's choice with every candidate's
scores, and the lane-change NRMSE of each fit. ``--plant ideal``: the simulator's ideal plant (tyre
slip only) instead of its defaults; ``--plant mujoco``: the MuJoCo plant (``simulate(engine="mujoco")``,
the MJCF generated from the default platform and the true parameters; the truth of the errors is the
MuJoCo vehicle's lumped parameters as the log's sidecar gives them, checked against
``SimulationResult.true_model``; no breakaway cases, ``all`` included: MuJoCo's joint friction is its
dry ``frictionloss``). ``--delay-probe``: on the effect-free cases also a delay fit searched over
:data:`PROBE_RANGE` (negative delays included: the apparent delay of a log without one, the offset
a real delay is found with); ``--rows stick-slip``: every fit with the rows for stick-slip logs
(docs/identification.md, "Breakaway friction"; ``auto`` then with the Stribeck fit's ``stiction_threshold``
0.005 for every candidate, the paper's included: the rows reach into the Stribeck range). Records go to
``--records`` (JSON lines, one per seed, case, plant and rows; a later one replaces an earlier one), so
runs can be split and merged; ``--report-only`` renders the tables from the records. The cases and the
acceptance checks and tables: ``study_model_extensions_cases.py``; the measured figures: docs/identification.md,
"The model beyond the paper (issue 30)".

Run (2 cores shared: nice)::

    nice -n 10 .venv/bin/python benchmarks/study_model_extensions.py --seeds 1 2 --records r.jsonl --markdown
    nice -n 10 .venv/bin/python benchmarks/study_model_extensions.py --seeds 1-10 --cases none delay6 \\
        --records r.jsonl --compare-seeds 5
    .venv/bin/python benchmarks/study_model_extensions.py --records r.jsonl --report-only --markdown --json s.json
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

from agvdyn.identification import (IdentificationSettings, ImplausibleError, UnidentifiableError, compare_models,
                                   identify, identify_model)
from agvdyn.identification.selection import chosen_model
from agvdyn.io import load_logs
from agvdyn.io.log import read_sidecar
from agvdyn.model_spec import PAPER_MODEL, ModelSpec
from agvdyn.simulation import simulate
from agvdyn.validation import validate

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_model_extensions_cases import (CASES, ENGINES, ESTIMATED, PLANTS, STRIBECK, Case, checks,  # noqa: E402
                                          plant_refusal, read_records, reference_case, render)

#: The rows of the fits: the defaults, or those for stick-slip logs (benchmarks/study_breakaway.py,
#: docs/identification.md "Breakaway friction"; the Stribeck model also with stiction_threshold 0.005).
ROWS = {"default": {}, "stick-slip": dict(filtering="matched", steering_guard=12.0)}
#: Seed offsets of the car-like and the lane-change logs.
CAR_LIKE_SEED, LANE_SEED = 1000, 2000
#: The delay range (s) of ``--delay-probe``: both signs, 5 sample periods below 0, 10 above.
PROBE_RANGE = (-0.01, 0.02)


def _finite(x: Any) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def simulated_logs(case: Case, seed: int, out: Path, name: str, plant: str) -> tuple[list, Any, Any]:
    """``(fit logs, lane-change log, truth)``: the logs written to ``out`` and loaded back (the CLI's path)."""
    settings, engine = case.settings(plant), ENGINES[plant]
    name = f"{name}_{plant}"
    result = simulate("identification", settings=settings, seed=seed, engine=engine)
    paths = [result.write(out / f"seed{seed}_{name}.parquet")]
    if case.car_like:
        paths.append(simulate("car-like", settings=settings, seed=CAR_LIKE_SEED + seed, engine=engine)
                     .write(out / f"seed{seed}_{name}_carlike.parquet"))
    lane = simulate("lane-change", settings=settings, seed=LANE_SEED + seed, engine=engine).write(
        out / f"seed{seed}_{name}_lane.parquet")
    return load_logs(paths), load_logs([lane])[0], checked_truth(result, paths[0], engine)


def checked_truth(result: Any, path: Path, engine: str) -> Any:
    """The log's true model (:attr:`SimulationResult.true_model`: on MuJoCo the vehicle's lumped
    parameters), checked against the sidecar written beside ``path``: its engine and true parameters."""
    side, truth = read_sidecar(path), result.true_model
    written = {**truth.parameters.to_dict(), **truth.extra}
    if side.get("engine") != engine or side.get("true_parameters") != written:
        raise SystemExit(f"{path}: the sidecar's engine {side.get('engine')!r} and true_parameters "
                         f"{side.get('true_parameters')} differ from the run's ({engine!r}, {written})")
    return truth


def lane_nrmse(lane: Any, model: Any, settings: IdentificationSettings) -> dict[str, float | None]:
    """Lane-change NRMSE per coordinate without stiction rows (:func:`agvdyn.validation.validate`) and their mean."""
    table = validate(lane, model, settings=settings).nrmse_moving
    values = [v for v in table.values() if math.isfinite(v)]
    return {**{k.split(":")[-1]: _finite(v) for k, v in table.items()},
            "mean": float(sum(values) / len(values)) if values else None}


def fit_record(ident: Any, truth: Any, lane: Any, seconds: float) -> dict[str, Any]:
    """A fit's errors against the truth (paper parameters, the effect's values) and its lane-change NRMSE."""
    true = truth.parameters
    rec: dict[str, Any] = {"model": ident.model.label, "seconds": round(seconds, 2),
                           "error_pct": {}, "error_std": {}, "warnings": len(ident.warnings)}
    for n in ESTIMATED:
        value, std = getattr(ident.parameters, n), ident.std.get(n, math.inf)
        rec["error_pct"][n] = 100 * (value / getattr(true, n) - 1)
        rec["error_std"][n] = _finite((value - getattr(true, n)) / std) if std > 0 else None
    spec = ident.model
    if spec.delay != 0.0:
        rec["delay_s"], rec["delay_std_s"] = float(spec.delay), _finite(ident.delay_std_s)
    for n, v in ident.extra.items():
        rec.setdefault("extra", {})[n] = {"value": v, "std": _finite(ident.extra_std.get(n, math.inf)),
                                          "true": truth.value(n)}
    rec["lane_nrmse"] = lane_nrmse(lane, ident.model_parameters, ident.settings)
    return rec


def auto_record(logs: list, truth: Any, lane: Any, paper: Any, settings: IdentificationSettings) -> dict[str, Any]:
    """``compare_models`` with the lane change as validation score: the choice, each candidate's scores,
    the chosen fit's record and how far its paper parameters are from the paper fit's."""
    t0 = time.perf_counter()
    try:
        selection = compare_models(logs, settings=settings,
                                   validation=lambda ident: lane_nrmse(lane, ident.model_parameters, settings)["mean"])
    except Exception as exc:  # noqa: BLE001 - a study records what fails, named (see the report)
        return {"error": _message(exc), "seconds": round(time.perf_counter() - t0, 2)}
    ident = selection.identification
    rec = fit_record(ident, truth, lane, time.perf_counter() - t0)
    rec["chosen"] = selection.model.label
    before, scores = chosen_model(list(selection.scores), rows="all")  # the same scores, compared on all rows
    rec["chosen_all_rows"] = scores[before].label
    rec["candidates"] = [s.to_dict() for s in selection.scores]
    rec["correlation_steps"] = selection.correlation_steps
    rec["paper_change"] = None if paper is None else max(
        abs(getattr(ident.parameters, n) / getattr(paper.parameters, n) - 1) for n in ESTIMATED)
    return rec


def _message(exc: Exception) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())[:400]


def fit_settings(rows: str, model: ModelSpec = PAPER_MODEL) -> IdentificationSettings:
    """The settings of a fit with ``rows`` (:data:`ROWS`)."""
    extra = dict(stiction_threshold=0.005) if rows != "default" and model.stribeck else {}
    return IdentificationSettings.from_flat(**ROWS[rows], **extra)


def refused_or_lenient(fit: Callable[[IdentificationSettings], Any], settings: IdentificationSettings, truth: Any,
                       lane: Any) -> tuple[Any, dict[str, Any]]:
    """``fit`` with ``settings``; when it refuses the data (unidentifiable, implausible), the refusal
    recorded as ``refused`` and the figures of the same fit without refusals (as compare_models judges
    its candidates)."""
    t0 = time.perf_counter()
    try:
        ident = fit(settings)
        return ident, fit_record(ident, truth, lane, time.perf_counter() - t0)
    except (UnidentifiableError, ImplausibleError) as exc:
        refused = _message(exc)
    try:
        ident = fit(settings.replace(plausibility=False, unexcited="report", max_relative_std=math.inf))
    except Exception as exc:  # noqa: BLE001 - a study records what fails, named
        return None, {"error": _message(exc), "refused": refused}
    return ident, {**fit_record(ident, truth, lane, time.perf_counter() - t0), "refused": refused}


def run_one(seed: int, name: str, out: Path, compare: bool, plant: str, rows: str = "default",
            probe: bool = False) -> dict[str, Any]:
    """One seed of one case: simulate, fit paper / extension / auto (and the delay probe), record."""
    case = CASES[name]
    if plant_refusal(case, plant) is not None:
        raise SystemExit(f"case {name}: {plant_refusal(case, plant)}")
    logs, lane, truth = simulated_logs(case, seed, out, name, plant)
    rec: dict[str, Any] = {"seed": seed, "case": name, "plant": plant, "rows": rows, "sample_time": float(logs[0].sample_time),
                           "true_delay_s": truth.delay_s, "engine": ENGINES[plant],
                           "true_parameters": {**truth.parameters.to_dict(), **truth.extra}, "fits": {}}
    base = fit_settings(rows)
    paper, rec["fits"]["paper"] = refused_or_lenient(lambda s: identify(logs, settings=s), base, truth, lane)
    if not case.extension.is_paper:
        _, rec["fits"]["extension"] = refused_or_lenient(
            lambda s: identify_model(logs, model=case.extension, settings=s), fit_settings(rows, case.extension),
            truth, lane)
    if probe and case.extension.is_paper:  # the apparent delay of a log without one
        _, rec["fits"]["delay_probe"] = refused_or_lenient(
            lambda s: identify_model(logs, model=ModelSpec(delay="auto", delay_range=PROBE_RANGE), settings=s), base,
            truth, lane)
    if compare:  # with the stick-slip rows also the Stribeck fit's stiction threshold: the rows reach its range
        settings = fit_settings(rows, STRIBECK)
        if settings != base:  # "parameters unchanged": against the paper's fit on the same rows
            paper = refused_or_lenient(lambda s: identify(logs, settings=s), settings, truth, lane)[0]
        rec["fits"]["auto"] = auto_record(logs, truth, lane, paper, settings)
    return rec


def _seeds(texts: list[str]) -> list[int]:
    out: list[int] = []
    for text in texts:
        lo, _, hi = text.partition("-")
        try:
            out += list(range(int(lo), int(hi or lo) + 1))
        except ValueError:
            raise SystemExit(f"--seeds {text!r}: expected an integer or a range LO-HI") from None
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", default=["1", "2"], help="sensor-noise seeds (N or LO-HI)")
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES), help="effects")
    ap.add_argument("--plant", choices=PLANTS, default="default",
                    help="the simulator's default plant, its ideal one (tyre slip only) or the MuJoCo plant "
                         "(engine mujoco); breakaway cases on the default plant only")
    ap.add_argument("--delay-probe", action="store_true",
                    help=f"effect-free cases: also a delay fit searched in {PROBE_RANGE} s (the apparent delay)")
    ap.add_argument("--rows", choices=list(ROWS), default="default",
                    help="the rows of every fit: default, or stick-slip (filtering matched, steering guard 12)")
    ap.add_argument("--out", type=Path, default=None, help="folder of the logs (default: a temporary one)")
    ap.add_argument("--compare-seeds", type=int, default=None,
                    help="run compare_models (auto) on the first N seeds only (default: all)")
    ap.add_argument("--records", type=Path, default=None, help="JSON-lines file the records are appended to")
    ap.add_argument("--report-only", action="store_true", help="render the tables of --records, no runs")
    ap.add_argument("--markdown", action="store_true", help="print the tables as markdown")
    ap.add_argument("--json", type=Path, default=None, help="write every record and its checks as JSON")
    args = ap.parse_args()
    records = read_records(args.records)
    refused = [f"{name}: {plant_refusal(CASES[name], args.plant)}" for name in args.cases
               if plant_refusal(CASES[name], args.plant) is not None]
    if refused and not args.report_only:
        raise SystemExit(f"--plant {args.plant} cannot run these cases:\n  " + "\n  ".join(refused))
    if not args.report_only:
        with tempfile.TemporaryDirectory(prefix="agvdyn-study-") as tmp:
            out = args.out or Path(tmp)
            out.mkdir(parents=True, exist_ok=True)
            for name in args.cases:
                for k, seed in enumerate(_seeds(args.seeds)):
                    t0 = time.perf_counter()
                    rec = run_one(seed, name, out, args.compare_seeds is None or k < args.compare_seeds, args.plant,
                                  args.rows, args.delay_probe)
                    rec["wall_s"] = round(time.perf_counter() - t0, 1)
                    records[(seed, name, args.plant, args.rows)] = rec
                    ref = records.get((seed, reference_case(name), args.plant, args.rows))
                    print(f"{name} {args.plant} {args.rows} seed {seed}: {rec['wall_s']} s {checks(rec, ref)}", flush=True)
                    if args.records:
                        with args.records.open("a", encoding="utf-8") as f:
                            f.write(json.dumps(rec) + "\n")
    render(records, args.markdown, args.json)


if __name__ == "__main__":
    sys.exit(main())
