"""`make demo`: the main job end to end on the built-in prototype."""
from __future__ import annotations

import sys

import numpy as np

from agvdyn.dynamics import feedforward_torques
from agvdyn.identifiability import table1
from agvdyn.kinematics import Mode, steering_from_virtual
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE


def _section(title: str) -> None:
    print(f"\n=== {title} ===")


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


def main() -> int:
    show_model()
    return 0


if __name__ == "__main__":
    sys.exit(main())
