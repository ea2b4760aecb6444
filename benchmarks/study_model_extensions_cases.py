"""The cases and the acceptance tables of ``study_model_extensions.py`` (issue 30).

A case is an effect of :mod:`agvdyn.model_spec` on our plant and the extension that models it
(:data:`CASES`); :func:`checks` says per seed what meets the issue's acceptance, :func:`metrics` gives
the figures, :func:`summary_table` / :func:`case_table` the markdown tables (median and worst over
seeds). The paper's parameters are judged against the truth and against the effect-free fit of the
same seed (:func:`reference_case`): our default plant has model errors of its own.
"""
from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from agvdyn.model_spec import BREAKAWAY_NAMES, PAPER_MODEL, ModelSpec
from agvdyn.platform import PARAMETER_NAMES
from agvdyn.simulation import SimulationSettings
from agvdyn.simulation.payload import PayloadEvent

#: The paper's 10 estimated parameters (B_w fixed) and the acceptance tolerances (fraction of the truth).
ESTIMATED = tuple(n for n in PARAMETER_NAMES if n != "B_w")
TOLERANCE = {"C_l": 0.05, "C_r": 0.05, "m_ch": 0.005, "C_ch": 0.005,
             **{n: 0.02 for n in ("d_vl", "d_cl", "d_vr", "d_cr", "d_vw", "d_cw")}}
#: The effect's tolerances: delay within one sample period, y_c within 1 cm, d_s within 10 %.
DELAY_TOL_SAMPLES, Y_C_TOL_M, D_S_TOL = 1.0, 0.01, 0.10


def box_payload(mass: float, x: float, y: float) -> PayloadEvent:
    """A load of ``mass`` kg centred at (x, y) m from t = 0, yaw inertia of a 0.8 x 0.6 m box (as effect_logs)."""
    return PayloadEvent(t=0.0, mass=mass, x=x, y=y, inertia=mass * (0.8**2 + 0.6**2) / 12)


@dataclass(frozen=True)
class Case:
    """An effect on our plant and the extension that models it."""

    delay: float = 0.0
    payload: PayloadEvent | None = None
    breakaway: tuple[float, float] | None = None  # (ratio d_s / d_c, Stribeck velocity rad/s), all joint groups
    car_like: bool = False
    extension: ModelSpec = PAPER_MODEL

    def settings(self, plant: str = "default") -> SimulationSettings:
        """The simulation settings: the simulator's defaults (``plant="default"``: stick-slip, steering-unit
        masses, torque limit, wheel radius errors), its ideal plant (tyre slip only), or the defaults for
        the MuJoCo plant (``"mujoco"``: of the plant settings MuJoCo takes the wheel radius errors only),
        with the effect."""
        refusal = plant_refusal(self, plant)
        if refusal is not None:
            raise ValueError(refusal)
        s = SimulationSettings()
        if plant == "ideal":
            s = replace(s, plant=s.plant.ideal())
        if self.breakaway is not None:
            s = replace(s, plant=s.plant.with_breakaway("all", *self.breakaway))
        if self.delay:
            s = replace(s, sensors=replace(s.sensors, torque_delay=self.delay))
        if self.payload is not None:
            s = replace(s, payload=(self.payload,))
        return s


#: The plants of the study: our simulator's defaults, its ideal plant, and the MuJoCo plant (the
#: MJCF generated from the default platform and the true parameters; ``simulate(engine="mujoco")``).
PLANTS = ("default", "ideal", "mujoco")
#: The ``simulate`` engine of each plant.
ENGINES = {"default": "ours", "ideal": "ours", "mujoco": "mujoco"}


def plant_refusal(case: Case, plant: str) -> str | None:
    """Why ``case`` cannot run on ``plant`` (None when it can): breakaway friction needs a stick-slip law,
    our default plant's or MuJoCo's (its dry ``frictionloss`` at the static level plus a Stribeck assist,
    src/agvdyn/simulation/mujoco_friction.py); the ideal plant has none."""
    if plant not in PLANTS:
        return f"plant {plant!r}: expected one of {list(PLANTS)}"
    if case.breakaway is None or plant == "default":
        return None
    if plant == "ideal":
        return "breakaway friction needs stick-slip (the ideal plant has none): use --plant default or mujoco"
    return None


P150, P200 = box_payload(150.0, 0.15, -0.10), box_payload(200.0, 0.0, 0.20)
STRIBECK, DELAY, OFFSET = ModelSpec(friction="stribeck"), ModelSpec(delay="auto"), ModelSpec(com_offset=True)
CASES = {
    "none": Case(),
    "none_carlike": Case(car_like=True),
    "delay2": Case(delay=0.002, extension=DELAY),
    "delay6": Case(delay=0.006, extension=DELAY),
    "delay10": Case(delay=0.010, extension=DELAY),
    "payload150": Case(payload=P150, car_like=True, extension=OFFSET),
    "payload200": Case(payload=P200, car_like=True, extension=OFFSET),
    "breakaway1.2": Case(breakaway=(1.2, 0.02), extension=STRIBECK),
    "breakaway1.3": Case(breakaway=(1.3, 0.05), extension=STRIBECK),
    "breakaway1.5": Case(breakaway=(1.5, 0.1), extension=STRIBECK),
    "all": Case(delay=0.006, payload=P150, breakaway=(1.3, 0.05), car_like=True,
                extension=ModelSpec(friction="stribeck", delay="auto", com_offset=True)),
}


FRICTIONS = ("d_vl", "d_cl", "d_vr", "d_cr", "d_vw", "d_cw")
GROUPS = {"m_ch, C_ch 0.5 %": ("m_ch", "C_ch"), "frictions 2 %": FRICTIONS, "C_l, C_r 5 %": ("C_l", "C_r")}


def reference_case(name: str) -> str:
    """The effect-free case of the same fit data (identification, and car-like when the case has it)."""
    return "none_carlike" if CASES[name].car_like else "none"


def _within(err: dict[str, float], names: tuple[str, ...]) -> bool:
    return all(abs(err[n]) <= 100 * TOLERANCE[n] for n in names)


def _shift(fit: dict[str, Any], ref: dict[str, Any] | None) -> dict[str, float] | None:
    """Percentage points by which a fit's errors differ from the effect-free paper fit of the same seed
    (the bias the effect leaves, our plant's own model errors taken out)."""
    if ref is None or "error" in fit:
        return None
    base = ref["fits"]["paper"]["error_pct"]
    return {n: fit["error_pct"][n] - base[n] for n in ESTIMATED}


def checks(rec: dict[str, Any], ref: dict[str, Any] | None = None) -> dict[str, bool | None]:
    """Per seed, what meets the acceptance: the paper's parameters of the extension's fit (the paper
    fit's for an effect-free case) against the truth and against the effect-free fit ``ref`` of the
    same seed; the effect's values; auto's choice."""
    fits, case = rec["fits"], CASES[rec["case"]]
    target = fits.get("extension", fits["paper"])
    if "error" in target:
        return {"fitted": False}
    out: dict[str, bool | None] = {"fitted without refusal": "refused" not in target}
    for label, names in GROUPS.items():
        out[f"{label} (truth)"] = _within(target["error_pct"], names)
    shift = _shift(target, ref) if not case.extension.is_paper else None
    if shift is not None:
        for label, names in GROUPS.items():
            out[f"{label} (vs effect-free)"] = _within(shift, names)
    extra = target.get("extra", {})
    if case.delay:
        out["delay within 1 sample"] = abs(target["delay_s"] - rec["true_delay_s"]) <= DELAY_TOL_SAMPLES * rec["sample_time"]
        out["delay std finite"] = target["delay_std_s"] is not None
    if case.payload is not None:
        out["y_c within 1 cm"] = abs(extra["y_c"]["value"] - extra["y_c"]["true"]) <= Y_C_TOL_M
        out["x_c std inf"] = extra["x_c"]["std"] is None
    if case.breakaway is not None:
        out["d_sw within 10 %"] = abs(extra["d_sw"]["value"] / extra["d_sw"]["true"] - 1) <= D_S_TOL
        out["d_sw held (std inf)"] = extra["d_sw"]["std"] is None
        out["d_sl, d_sr within 10 %"] = all(abs(extra[n]["value"] / extra[n]["true"] - 1) <= D_S_TOL
                                            for n in ("d_sl", "d_sr"))
        out["d_sl, d_sr std inf (no support)"] = all(extra[n]["std"] is None for n in ("d_sl", "d_sr"))
    auto = fits.get("auto")
    if auto is not None:
        wanted = "paper" if case.extension.is_paper else case.extension.label
        out[f"auto chooses {wanted}"] = "error" not in auto and auto["chosen"] == wanted
        if "chosen_all_rows" in auto:
            out[f"auto on all rows chooses {wanted}"] = auto["chosen_all_rows"] == wanted
        if case.delay and "delay_s" in auto:  # auto kept a delay: within one sample of the truth
            error = abs(auto["delay_s"] - rec["true_delay_s"])
            out["auto's delay within 1 sample"] = error <= DELAY_TOL_SAMPLES * rec["sample_time"]
        if case.extension.is_paper:
            out["auto: parameters unchanged"] = "error" not in auto and auto["paper_change"] is not None and auto["paper_change"] < 1e-12
    return out


def metrics(rec: dict[str, Any], ref: dict[str, Any] | None = None) -> dict[str, float | None]:
    """The figures of the table per seed (signed: the worst is the largest magnitude)."""
    out: dict[str, float | None] = {}
    for label, fit in rec["fits"].items():
        if "error" in fit:
            continue
        shift = _shift(fit, ref) if rec["case"] != reference_case(rec["case"]) else None
        for n in ESTIMATED:
            out[f"{label} {n} %"] = fit["error_pct"][n]
            if shift is not None:
                out[f"{label} {n} % vs effect-free"] = shift[n]
        out[f"{label} lane NRMSE"] = fit["lane_nrmse"]["mean"]
        if "delay_s" in fit:
            out[f"{label} delay error (samples)"] = (fit["delay_s"] - rec["true_delay_s"]) / rec["sample_time"]
            out[f"{label} delay std (samples)"] = (math.inf if fit["delay_std_s"] is None
                                                   else fit["delay_std_s"] / rec["sample_time"])
        for n, e in fit.get("extra", {}).items():
            if n == "y_c":
                out[f"{label} y_c error (cm)"] = 100 * (e["value"] - e["true"])
                out[f"{label} y_c std (cm)"] = math.inf if e["std"] is None else 100 * e["std"]
            elif n == "x_c":
                out[f"{label} x_c std (cm)"] = math.inf if e["std"] is None else 100 * e["std"]
            elif n in BREAKAWAY_NAMES:
                out[f"{label} {n} %"] = 100 * (e["value"] / e["true"] - 1)
    return out


def _stat(values: list[float | None]) -> tuple[str, str]:
    finite = [v for v in values if v is not None]
    if not finite:
        return "-", "-"
    worst = max(finite, key=lambda v: abs(v) if math.isfinite(v) else math.inf)
    return f"{statistics.median(finite):+.3g}", f"{worst:+.3g}"


def case_table(records: list[dict[str, Any]], refs: dict[int, dict[str, Any]]) -> list[str]:
    """Markdown lines of one case: median and worst over seeds of each figure, seeds meeting each check."""
    r0 = records[0]
    seeds = sorted(r["seed"] for r in records)
    lines = [f"#### {r0['case']}, {r0['plant']} plant, {r0.get('rows', 'default')} rows ({len(seeds)} seeds: {', '.join(map(str, seeds))})", "",
             "| figure | median | worst |", "|---|---|---|"]
    per_seed = [metrics(r, refs.get(r["seed"])) for r in records]
    for key in dict.fromkeys(k for m in per_seed for k in m):
        median, worst = _stat([m.get(key) for m in per_seed])
        lines.append(f"| {key} | {median} | {worst} |")
    lines += ["", "| acceptance | seeds meeting |", "|---|---|"]
    results = [checks(r, refs.get(r["seed"])) for r in records]
    for key in dict.fromkeys(k for c in results for k in c):
        got = [c[key] for c in results if c.get(key) is not None]
        lines.append(f"| {key} | {sum(got)}/{len(got)} |")
    autos = [r["fits"]["auto"] for r in records if "auto" in r["fits"]]
    if autos:
        chosen: dict[str, int] = {}
        for a in autos:
            key = a.get("chosen") or "failed: " + a["error"][:100]
            chosen[key] = chosen.get(key, 0) + 1
        lines.append(f"| auto chose | {'; '.join(f'{k} x{v}' for k, v in chosen.items())} |")
    return lines + [""]


def _effect_cell(recs: list[dict[str, Any]], refs: dict[int, Any]) -> str:
    """The effect's recovery: median (worst) of its error, for the target fit of each seed."""
    keys = ("extension delay error (samples)", "extension y_c error (cm)", "extension d_sl %", "extension d_sr %",
            "extension d_sw %")
    per_seed = [metrics(r, refs.get(r["seed"])) for r in recs]
    cells = []
    for key in keys:
        median, worst = _stat([m.get(key) for m in per_seed])
        if median != "-":
            cells.append(f"{key.split(' ', 1)[1].replace(' error', '')} {median} ({worst})")
    return "; ".join(cells) or "-"


def summary_table(records: dict[Key, dict[str, Any]], plant: str, rows: str) -> list[str]:
    """One line per case: the effect's recovery, the seeds meeting each check, auto's choices, and the
    lane-change NRMSE of the paper fit and of the extension's (medians)."""
    lines = [f"| case ({plant} plant, {rows} rows) | seeds | effect: median (worst) | meets (seeds) | auto chose | "
             "auto on all rows chose | lane NRMSE paper / extension / auto |", "|---|---|---|---|---|---|---|"]
    for name in CASES:
        recs = sorted((r for k, r in records.items() if k[1:] == (name, plant, rows)), key=lambda r: r["seed"])
        if not recs:
            continue
        refs = {r["seed"]: records.get((r["seed"], reference_case(name), plant, rows)) for r in recs}
        results = [checks(r, refs.get(r["seed"])) for r in recs]
        meets = []
        for key in dict.fromkeys(k for c in results for k in c):
            got = [c[key] for c in results if c.get(key) is not None]
            meets.append(f"{key} {sum(got)}/{len(got)}")
        chosen: dict[str, int] = {}
        before: dict[str, int] = {}
        for a in (r["fits"]["auto"] for r in recs if "auto" in r["fits"]):
            label = a.get("chosen") or a["error"].split(":")[0]
            chosen[label] = chosen.get(label, 0) + 1
            if "chosen_all_rows" in a:
                before[a["chosen_all_rows"]] = before.get(a["chosen_all_rows"], 0) + 1
        nrmse = [statistics.median([r["fits"][f]["lane_nrmse"]["mean"] for r in recs if f in r["fits"]
                                    and "lane_nrmse" in r["fits"][f]] or [math.nan]) for f in ("paper", "extension", "auto")]
        lines.append(f"| {name} | {len(recs)} | {_effect_cell(recs, refs)} | {'; '.join(meets)} | "
                     f"{', '.join(f'{k} {v}' for k, v in chosen.items()) or '-'} | "
                     f"{', '.join(f'{k} {v}' for k, v in before.items()) or '-'} | "
                     f"{nrmse[0]:.4f} / {nrmse[1]:.4f} / {nrmse[2]:.4f} |".replace("nan", "-"))
    return lines + [""]


Key = tuple[int, str, str, str]


def read_records(path: Path | None) -> dict[Key, dict[str, Any]]:
    """The records of a JSON-lines file, the last one of each (seed, case, plant)."""
    latest: dict[Key, dict[str, Any]] = {}
    if path is not None and path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            if line.strip():
                rec = json.loads(line)
                latest[(rec["seed"], rec["case"], rec["plant"], rec.get("rows", "default"))] = rec
    return latest


def render(records: dict[Key, dict[str, Any]], markdown: bool, json_path: Path | None) -> None:
    """The tables per plant and case (markdown) and the JSON of every record with its checks."""
    def ref(key: Key) -> dict[str, Any] | None:
        return records.get((key[0], reference_case(key[1]), *key[2:]))

    if markdown:
        for plant, rows in sorted({k[2:] for k in records}):
            print("\n".join(summary_table(records, plant, rows)))
        for plant, rows in sorted({k[2:] for k in records}):
            for name in CASES:
                recs = sorted((r for k, r in records.items() if k[1:] == (name, plant, rows)), key=lambda r: r["seed"])
                if recs:
                    table_refs = {r["seed"]: ref((r["seed"], name, plant, rows)) for r in recs}
                    print("\n".join(case_table(recs, table_refs)))
    if json_path is not None:
        table = [{"seed": k[0], "case": k[1], "plant": k[2], "rows": k[3], **checks(r, ref(k))} for k, r in records.items()]
        json_path.write_text(json.dumps({"records": list(records.values()), "checks": table}, indent=1), encoding="utf-8")
