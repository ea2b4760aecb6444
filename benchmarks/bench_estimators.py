"""Cost of each estimator and uncertainty method per million equation rows.

A stacked system like the identification's (14 columns: 10 parameters and 4 offsets; rows in
6 generalized-coordinate groups with residual levels 0.07-2.5 N m; residuals correlated over
~100 samples; 2 rows per time step) is fitted by every estimator, then the covariance of the
default estimator by every uncertainty method. Figures in seconds per 10^6 rows, single process.

Run: ``.venv/bin/python benchmarks/bench_estimators.py [--rows 1000000]``.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from agvdyn.identification.estimators import ESTIMATORS, make_estimator  # noqa: E402
from agvdyn.identification.normal import RegressionData, RowIndex
from agvdyn.identification.uncertainty import UncertaintyMethod, parameter_uncertainty  # noqa: E402


def system(m: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    p = 14
    A = rng.standard_normal((m, p)) * np.logspace(-2, 3, p)
    group = rng.integers(0, 6, m)
    level = np.array([0.07, 0.08, 2.5, 2.9, 1.0, 0.5])[group]
    kernel = np.ones(100) / 10.0
    e = np.convolve(rng.standard_normal(m + 99), kernel, mode="valid") * level
    y = A @ rng.uniform(0.5, 2.0, p) + e
    index = RowIndex(group, tuple("g%d" % i for i in range(6)), np.zeros(m, dtype=np.int64), np.arange(m) // 2)
    names = ["C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr", "m_ch", "C_ch", "d_vw", "d_cw", "o1", "o2", "o3", "o4"]
    return A, y, index, names


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", type=int, default=1_000_000)
    args = parser.parse_args()
    A, y, index, names = system(args.rows)
    per = 1e6 / args.rows
    print(f"{args.rows:,} rows x {A.shape[1]} columns")
    fitted = {}
    for name in ESTIMATORS:
        est = make_estimator(name)
        t0 = time.perf_counter()
        est.fit(A, y, groups=index.group, names=names)
        dt = time.perf_counter() - t0
        fitted[name] = est
        extra = f", {getattr(est, 'n_iter_', 1)} iterations" if hasattr(est, "n_iter_") else ""
        print(f"estimator {name:8s} {dt * per:7.3f} s per 10^6 rows{extra}")
    # what identify() does: rows reduced to triangular factors per coordinate once, then the fit on
    # the pseudo-rows (same answer); the factors cost once per row, the fit no longer depends on rows
    from agvdyn.identification.normal import RowStatistics, regression_data  # noqa: PLC0415

    t0 = time.perf_counter()
    stats = RowStatistics(A.shape[1])
    for g in range(len(index.group_names)):
        sel = index.group == g
        stats.add(("s", index.group_names[g]), np.column_stack([A[sel], y[sel]]))
    data = regression_data(stats, {n: i for i, n in enumerate(index.group_names)}, range(A.shape[1]),
                           np.zeros(A.shape[1]), None)
    t_factor = time.perf_counter() - t0
    for name in ("ols", "wls", "bounded"):
        t0 = time.perf_counter()
        est = make_estimator(name).fit(data.A, data.y, groups=data.group, names=names, group_rows=data.group_rows,
                                       n_rows=data.n_rows)
        dt = time.perf_counter() - t0
        gap = np.max(np.abs(est.coef_ / fitted[name].coef_ - 1))
        print(f"estimator {name:8s} on pseudo-rows: {t_factor * per:.3f} s per 10^6 rows to factor + {dt * 1e3:.1f} ms "
              f"to fit ({data.A.shape[0]} pseudo-rows; coefficients equal to {gap:.1e})")
    for method in UncertaintyMethod:
        t0 = time.perf_counter()
        unc = parameter_uncertainty(method, fitted["wls"], RegressionData.from_rows(A, y, index))
        dt = time.perf_counter() - t0
        bw = unc.details.get("bandwidth_steps", "-")
        print(f"uncertainty {method.value:9s} {dt * per:7.3f} s per 10^6 rows (bandwidth {bw})")


if __name__ == "__main__":
    main()
