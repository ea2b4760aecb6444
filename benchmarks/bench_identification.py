"""Benchmark: a 30-minute log at 500 Hz (900,000 samples, the four identification segments) from
load to parameters, and the ratio against a straightforward per-sample implementation.

Target (issue 4): under 2 s on one core from ``load_log`` to the parameters.

The per-sample reference builds, in a Python loop over samples, ``H_k^T Theta`` of one sample
from the core's ``kinematic_model`` and ``regressor`` (eq. 16, 19) and ``H_k^T B u``, then solves
the same least-squares problem. It runs on a subset of every segment (it takes ~0.1 ms per
sample) and its time is extrapolated linearly to the full log (it is linear in the samples).
Both are fed the same filtered signals, so the ratio compares the regression stage alone; the
end-to-end time (load, filters, odometry, regression) is printed too.

Run: ``.venv/bin/python benchmarks/bench_identification.py [--minutes 30]``.

``--acceptance``: instead, the acceptance of issue 4 on the project's simulator: identification
and lane-change logs simulated with Table 2 as the truth and sensor noise on, for several seeds,
with the simulator's neglected effects off (``PlantSettings().ideal()``) and on (defaults);
prints per parameter the deviation in % and in standard deviations and whether it is within
5 % or 3 std, and the lane-change NRMSE, for parallel and literal filtering.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from agvdyn.dynamics import input_matrix, regressor  # noqa: E402
from agvdyn.identification import (  # noqa: E402
    IdentificationSettings,
    equation_block,
    fit_blocks,
    identify,
    load_logs,
    log_equations,
)
from agvdyn.io import open_logs, write_log  # noqa: E402
from agvdyn.kinematics import kinematic_model  # noqa: E402
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE  # noqa: E402
from model_logs import identification_frame  # noqa: E402


def naive_rows(geometry, block_inputs, n_per_segment: int):
    """Per-sample loop: rows of H_k^T Theta and H_k^T B u, one sample at a time."""
    B = input_matrix(geometry)
    rows, rhs = [], []
    for mode, alpha, q_dot, q_ddot, u in block_inputs:
        for i in range(min(n_per_segment, alpha.shape[0])):
            H = kinematic_model(geometry, mode, alpha[i:i + 1])[0]          # (9, n_k)
            theta = regressor(q_dot[i:i + 1], q_ddot[i:i + 1])[0]           # (9, 11)
            HT = H.T
            rows.extend(HT @ theta)
            rhs.extend(HT @ (B @ u[i]))
    return np.array(rows), np.array(rhs)


def naive_inputs(log, settings) -> list:
    """Per run of one mode: (mode, alpha, q_dot, q_ddot, torque) of the filtered stretches of a log."""
    from agvdyn.identification.rows import row_modes  # noqa: PLC0415
    from agvdyn.identification.stretches import filtered_stretch, stretch_bounds  # noqa: PLC0415
    from agvdyn.kinematics import Mode  # noqa: PLC0415
    from agvdyn.signals import runs  # noqa: PLC0415

    inputs = []
    for a, b in stretch_bounds(log.t, log.alpha, log.beta, settings)[0]:
        st = filtered_stretch(PROTOTYPE, log, a, b, settings)
        modes = row_modes(PROTOTYPE, st, settings)
        q_ddot = np.concatenate([st.chassis_ddot, st.alpha_ddot, st.beta_ddot], axis=1)
        for c, d in runs(modes):
            if modes[c]:
                inputs.append((Mode(int(modes[c])), st.alpha[c:d], st.q_dot[c:d], q_ddot[c:d], st.torque[c:d]))
    return inputs


def acceptance(seeds: list[int]) -> None:
    """Identification on simulated logs against the simulator's truth (Table 2)."""
    from agvdyn.io import Log  # noqa: PLC0415
    from agvdyn.report import parameter_table  # noqa: PLC0415
    from agvdyn.simulation import PlantSettings, SimulationSettings, simulate  # noqa: PLC0415
    from agvdyn.validation import validate  # noqa: PLC0415

    for label, plant in (("neglected effects off", PlantSettings().ideal()), ("neglected effects on", PlantSettings())):
        settings = SimulationSettings(plant=plant)
        for seed in seeds:
            ident_sim = simulate("identification", settings=settings, seed=seed)
            lane_sim = simulate("lane-change", settings=settings, seed=seed + 1000)
            ident_log = Log.from_frame(ident_sim.log_frame(), sidecar=ident_sim.sidecar())
            lane_log = Log.from_frame(lane_sim.log_frame(), sidecar=lane_sim.sidecar())
            for filtering in ("parallel", "literal"):
                ident = identify(ident_log, settings=IdentificationSettings.from_flat(filtering=filtering))
                table = parameter_table(ident, PAPER_PARAMETERS, {}).drop(index="B_w")
                val = validate(lane_log, ident.parameters, settings=IdentificationSettings.from_flat(filtering=filtering))
                cells = " ".join(f"{n} {row.deviation_pct:+.1f}%/{row.deviation_in_std:.1f}s{'' if row.ok else '!'}"
                                 for n, row in table.iterrows())
                nrmse = " ".join(f"{k.split(':')[1]} {v:.3f}/{val.nrmse_moving[k]:.3f}" for k, v in val.nrmse.items())
                print(f"{label}, seed {seed}, {filtering}: {int(table.ok.sum())}/10 ok, cond {ident.condition_number:.2f}")
                print(f"   {cells}")
                print(f"   lane-change NRMSE all/without stiction: {nrmse}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=30.0, help="log duration (default 30)")
    parser.add_argument("--naive-samples", type=int, default=5000, help="per-sample loop: samples per segment")
    parser.add_argument("--acceptance", action="store_true", help="run the acceptance on simulated logs instead")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="seeds of the acceptance runs")
    args = parser.parse_args()
    if args.acceptance:
        acceptance(args.seeds)
        return
    seconds = args.minutes * 60 / 4
    durations = {name: seconds for name in ("steer_left", "steer_right", "straight", "rotation")}
    frame, _ = identification_frame(durations, repeats=max(1, int(seconds // 10)))  # 10 s excitation periods
    n = len(frame)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ident.parquet"
        write_log(path, frame, {"platform": PROTOTYPE.to_dict()})
        settings = IdentificationSettings()
        identify(open_logs(path), settings=settings)  # warm-up (imports, numba compilation of the core)
        t0 = time.perf_counter()
        ident = identify(open_logs(path), settings=settings)
        total = time.perf_counter() - t0
        # stage timings
        t0 = time.perf_counter()
        (log,) = load_logs([path])
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        blocks, _ = log_equations(log, PROTOTYPE, settings)
        t_signals = time.perf_counter() - t0
        t0 = time.perf_counter()
        fit_blocks(blocks, PROTOTYPE)
        t_fit = time.perf_counter() - t0
    err = max(abs(getattr(ident.parameters, k) / getattr(PAPER_PARAMETERS, k) - 1) for k in PARAMETER_NAMES)
    print(f"log: {n} samples ({args.minutes:g} min at 500 Hz), {ident.n_rows} equation rows")
    print(f"load -> parameters: {total:.3f} s  = {n / total / 1e6:.2f} M samples/s "
          f"(target < 2 s: {'met' if total < 2.0 else 'NOT met'})")
    print(f"  stages: load {t_load:.3f} s, signals + rows + filtering {t_signals:.3f} s, regression {t_fit:.3f} s")
    print(f"  largest relative parameter error on the noise-free model log: {err:.2e}")

    # same regression from the same filtered signals: vectorised vs per-sample
    inputs = naive_inputs(log, settings)
    t0 = time.perf_counter()
    vec_blocks = [equation_block(PROTOTYPE, m, a, qd, qdd, u, stiction_threshold=0.0) for m, a, qd, qdd, u in inputs]
    fit_blocks(vec_blocks, PROTOTYPE)
    t_vec = time.perf_counter() - t0
    m = args.naive_samples
    t0 = time.perf_counter()
    A, y = naive_rows(PROTOTYPE, inputs, m)
    keep = [i for i, name in enumerate(PARAMETER_NAMES) if name != "B_w"]
    np.linalg.lstsq(A[:, keep], y - A[:, -1] * 0.121, rcond=None)
    t_naive_subset = time.perf_counter() - t0
    done = sum(min(m, x[1].shape[0]) for x in inputs)
    t_naive = t_naive_subset * n / done
    print(f"regression stage from filtered signals, vectorised: {t_vec:.3f} s for {n} samples")
    print(f"per-sample loop: {t_naive_subset:.3f} s for {done} samples (subset), extrapolated to {n}: {t_naive:.1f} s")
    print(f"ratio per-sample / vectorised (regression stage): {t_naive / t_vec:.0f}x; "
          f"per-sample / whole vectorised pipeline: {t_naive / total:.0f}x")


if __name__ == "__main__":
    main()
