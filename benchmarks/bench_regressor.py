"""Benchmark: H_k^T Theta for 10^6 samples per mode (issue 2 target: >= 5e6 samples/s on one core).

Prints samples per second of ``projected_regressor`` (H_k and Theta from q, q_dot, q_ddot) and,
measured in the same run, of the direct evaluation ``einsum(H_k, Theta)`` with the dense regressor.
"""
from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from agvdyn.dynamics import projected_regressor, regressor  # noqa: E402
from agvdyn.kinematics import Mode, joint_motion, kinematic_model, max_virtual_angle, nominal_steering, steering_from_virtual  # noqa: E402
from agvdyn.platform import PROTOTYPE  # noqa: E402


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(n: int = 1_000_000) -> int:
    rng = np.random.default_rng(0)
    geom = PROTOTYPE
    print(f"H_k^T Theta for {n:,} samples, one core")
    worst = np.inf
    for mode in Mode:
        if mode is Mode.CAR_LIKE:
            alpha = steering_from_virtual(geom, rng.uniform(-0.9, 0.9, n) * max_virtual_angle(geom))
        elif mode is Mode.PARKING:
            alpha = rng.uniform(-1.5, 1.5, (n, 2))
        else:
            alpha = np.tile(nominal_steering(geom, mode), (n, 1))
        s = rng.normal(size=(2, n, mode.dof))
        q_dot, q_ddot = joint_motion(geom, mode, alpha, s[0], s[1])
        fast = best_of(lambda: projected_regressor(geom, mode, alpha, q_dot, q_ddot))
        m = n // 10
        dense = best_of(lambda: np.einsum("nik,nij->nkj", kinematic_model(geom, mode, alpha[:m]),
                                          regressor(q_dot[:m], q_ddot[:m])), repeat=1) * 10
        rate = n / fast
        worst = min(worst, rate)
        print(f"  mode {mode.label:>2}: {rate / 1e6:6.2f} M samples/s  (dense einsum: {n / dense / 1e6:5.2f} M/s, "
              f"speed-up {dense / fast:4.1f}x)")
    print(f"slowest mode: {worst / 1e6:.2f} M samples/s (target 5.00)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
