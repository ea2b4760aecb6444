"""`make demo`: the main job end to end on the built-in prototype.

Model (Table 1, feed-forward) -> simulate the identification sequence and the lane change on
the tyre-slip plant -> identify the parameters from the identification log -> validate them on
the lane change -> HTML report. Outputs go to ``demo_output/`` (or the directory given).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from agvdyn.dynamics import feedforward_torques
from agvdyn.identifiability import table1
from agvdyn.identification import identify, load_logs
from agvdyn.kinematics import Mode, steering_from_virtual
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE
from agvdyn.report import choose_reference, parameter_table, report_of, write_report
from agvdyn.simulation import simulate
from agvdyn.validation import validate


def _section(title: str) -> None:
    print(f"\n=== {title} ===", flush=True)


def show_model() -> None:
    geom, params = PROTOTYPE, PAPER_PARAMETERS
    _section(f"Platform {geom.name}: l={geom.l} m, b={geom.b} m, a={geom.a} m, r={geom.r} m, i_G={geom.i_G}")
    _section("Identifiability (Table 1)")
    for row in table1(geom):
        label = "{" + ", ".join(m.label for m in row.modes) + "}"
        print(f"{label:<12} rank {row.rank:>2}: {' '.join(row.identifiable)}")
    _section("Feed-forward motor torques (eq. 21), Table 2 parameters")
    alpha_v = np.array([0.0, 0.2, 0.4])
    u = feedforward_torques(geom, params, Mode.CAR_LIKE, steering_from_virtual(geom, alpha_v),
                            np.column_stack([np.full(3, 0.2), np.full(3, 1.0)]),
                            np.column_stack([np.zeros(3), np.full(3, 0.5)]))
    print("car-like mode, v_x = 1 m/s, a_x = 0.5 m/s^2, alpha_v_dot = 0.2 rad/s")
    for av, row in zip(alpha_v, u):
        print(f"  alpha_v = {av:4.2f} rad: M_mot (fl, rl, fr, rr) = {np.array2string(row, precision=3)} N m")


def run_pipeline(out_dir: Path) -> Path:
    """simulate -> identify -> validate -> report; returns the report's path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    logs = {}
    for experiment, seed in (("identification", 1), ("lane-change", 2)):
        _section(f"Simulate '{experiment}' (tyre-slip plant, stiction, steering-unit masses, sensor noise; seed {seed})")
        t0 = time.perf_counter()
        result = simulate(experiment, seed=seed)
        path = result.write(out_dir / f"{experiment}.parquet")
        track = result.tracking()
        print(f"{result.t[-1]:.1f} s of motion simulated in {time.perf_counter() - t0:.1f} s -> {path}")
        print("tracking errors per segment (SI units: rad, rad/s, m/s, m):")
        print(track.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
        logs[experiment] = path

    _section("Identify (eq. 22-25) from the identification log, B_w = 0.121 fixed")
    ident_logs = load_logs([logs["identification"]])
    ident = identify(ident_logs, check_rows=True)
    params_path = ident.write(out_dir / "params.yaml")
    reference = choose_reference(ident_logs, ident.geometry)
    table = parameter_table(ident, reference)
    label = reference.label if reference is not None else "no reference"
    print(f"compared with: {label}; cond(Theta_1w^T Theta_1w) = {ident.condition_number:.4g} (paper: 11.56)")
    shown = table[["value", "std", "reference", "deviation_pct"]].assign(
        ok=[("fixed" if v is None else "yes" if v else "no") for v in table["ok"]])
    print(shown.to_string(float_format=lambda x: f"{x:.5g}", na_rep="-"))
    print(f"-> {params_path}")

    _section("Validate on the lane change (car-like mode, not used for identification)")
    (val_log,) = load_logs([logs["lane-change"]])
    val = validate(val_log, ident.parameters)
    print(val.table[["nrmse", "nrmse_moving", "n_rows", "n_moving"]].to_string(
        float_format=lambda x: f"{x:.4g}", formatters={"n_rows": "{:,}".format, "n_moving": "{:,}".format}))
    print("nrmse: all rows; nrmse_moving: stiction rows left out (sec. 7)")

    report = report_of(ident, val, reference=reference, logs=ident_logs, validation_logs=[val_log],
                       command="make demo (python -m agvdyn.demo)")
    _section(f"Verdict: {report.verdict.outcome.value}")
    print(report.verdict.summary)
    for reason in report.verdict.reasons:
        print(f"  - {reason}")
    return write_report(out_dir / "report.html", report)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out_dir = Path(argv[0]) if argv else Path("demo_output")
    t0 = time.perf_counter()
    show_model()
    report = run_pipeline(out_dir)
    _section("Done")
    print(f"end to end in {time.perf_counter() - t0:.1f} s")
    print(f"report: {report.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
