"""Test vectors of the C++ feed-forward from the Python reference (STYLE.md rule 9).

Writes ``cpp/tests/vectors.json``: random configurations and desired motions per motion mode on
three vehicles, with the joint motion (eq. 4, 20) and the motor torques of eq. (21) that
``agvdyn.dynamics.feedforward_torques`` computes, plus invalid inputs and the error each must give.
The C++ tests (``ff_tests``, ctest) and the pytest suite (``tests/test_cpp_feedforward.py``) both
read this file. Regenerate after a change of the Python model::

    .venv/bin/python cpp/tests/make_vectors.py
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from agvdyn.dynamics import feedforward_torques
from agvdyn.kinematics import (
    MODE_TOLERANCE,
    STOP_TOLERANCE,
    Mode,
    joint_motion,
    max_virtual_angle,
    nominal_steering,
    steering_from_virtual,
)
from agvdyn.platform import EPSILON, PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Geometry, Parameters

PATH = Path(__file__).with_name("vectors.json")
DATA = Path(__file__).with_name("data")
SEED = 20240613
CASES_PER_MODE = 16
#: |u_cpp - u_python| <= RELATIVE * max|u_python| + ABSOLUTE, per case (N m).
RELATIVE = 1e-9
ABSOLUTE = 1e-12


def vehicles(rng: np.random.Generator) -> list[tuple[str, Geometry, Parameters]]:
    """The prototype with Table 2, an inboard offset with l < b, and a small vehicle; random parameters."""
    p = PAPER_PARAMETERS.to_vector()
    return [
        ("prototype", PROTOTYPE, PAPER_PARAMETERS),
        ("inboard", Geometry(l=0.7, b=1.1, a=-0.06, r=0.15, i_G=12.0, name="inboard"),
         Parameters.from_vector(p * rng.uniform(0.5, 1.5, p.size))),
        ("small", Geometry(l=1.0, b=0.7, a=0.04, r=0.09, i_G=20.0, name="small"),
         Parameters.from_vector(p * rng.uniform(0.5, 1.5, p.size))),
    ]


def configurations(geom: Geometry, mode: Mode, n: int, rng: np.random.Generator) -> np.ndarray:
    """Random steering angles (n, 2) in ``mode``: measured ones, off the exact relation within the tolerance,
    and the edges (mode 1 where the axle lines meet, mode 2 at the stops)."""
    tol = 0.9 * MODE_TOLERANCE
    if mode is Mode.PARKING:
        alpha = rng.uniform(-np.pi / 2, np.pi / 2, (n, 2))
        alpha[:4] = [[0.0, 0.0], [-geom.rotation_angle, geom.rotation_angle], [-np.pi / 2, np.pi / 2],
                     steering_from_virtual(geom, [0.3])[0]]
        return alpha
    if mode is Mode.CAR_LIKE:
        limit = max_virtual_angle(geom)
        av = rng.uniform(-0.98, 0.98, n) * limit
        av[:3] = [0.0, limit, -limit]
        alpha = steering_from_virtual(geom, av)
        alpha[3:] += rng.uniform(-0.3, 0.3, (n - 3, 2)) * tol  # measured: off the ICR relation
        return np.clip(alpha, -np.pi / 2, np.pi / 2)
    alpha = np.tile(nominal_steering(geom, mode), (n, 1))
    alpha[1:] += rng.uniform(-tol, tol, (n - 1, 2))
    return np.clip(alpha, -np.pi / 2, np.pi / 2)


def motions(mode: Mode, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """s_dot, s_ddot (n, dof): random, with rest, pure acceleration and creeping (tanh region) cases."""
    k = mode.dof
    s_dot = rng.uniform(-1.0, 1.0, (n, k))
    s_ddot = rng.uniform(-2.0, 2.0, (n, k))
    s_dot[0], s_ddot[0] = 0.0, 0.0
    s_dot[1] = 0.0
    s_dot[2] = rng.uniform(-1, 1, k) * 1e-3
    return s_dot, s_ddot


def _floats(x) -> list[float]:
    return [float(v) for v in np.ravel(x)]


def valid_cases(models, rng) -> list[dict[str, Any]]:
    cases = []
    for index, (_, geom, params) in enumerate(models):
        for mode in Mode:
            alpha = configurations(geom, mode, CASES_PER_MODE, rng)
            s_dot, s_ddot = motions(mode, CASES_PER_MODE, rng)
            u = feedforward_torques(geom, params, mode, alpha, s_dot, s_ddot)
            q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
            for j in range(CASES_PER_MODE):
                cases.append({"model": index, "mode": mode.label, "alpha": _floats(alpha[j]),
                              "s_dot": _floats(s_dot[j]), "s_ddot": _floats(s_ddot[j]),
                              "q_dot": _floats(q_dot[j]), "q_ddot": _floats(q_ddot[j]), "u": _floats(u[j])})
    return cases


def invalid_cases(models) -> list[dict[str, Any]]:
    """Inputs the Python model refuses (ValueError), with the C++ status each must give."""
    geom, params = models[0][1], models[0][2]
    rot = geom.rotation_angle
    off = 1.5 * MODE_TOLERANCE
    cases = [
        ("3", [0.0, 0.0], "not_in_mode"),
        ("3", [-np.pi / 2 + off, np.pi / 2], "not_in_mode"),
        ("4", [-rot, rot + off], "not_in_mode"),
        ("2s", [off, 0.0], "not_in_mode"),
        ("2", [0.3, -0.3], "not_in_mode"),
        ("2", list(steering_from_virtual(geom, [0.4])[0] + [off, -off]), "not_in_mode"),
        ("1", [np.pi / 2 + 1e-3, 0.0], "beyond_stop"),
        ("1", [0.0, -np.pi / 2 - 10 * STOP_TOLERANCE], "beyond_stop"),
        ("1", [math.nan, 0.0], "non_finite_input"),
        ("2s", [0.0, 0.0], "non_finite_input", [math.inf], [0.0]),
        ("4", [-rot, rot], "non_finite_input", [0.0], [math.nan]),
    ]
    out = []
    for spec in cases:
        label, alpha, status = spec[:3]
        mode = Mode.from_label(label)
        s_dot = spec[3] if len(spec) > 3 else [0.5] * mode.dof
        s_ddot = spec[4] if len(spec) > 4 else [0.1] * mode.dof
        try:
            feedforward_torques(geom, params, mode, np.array([alpha]), np.array([s_dot]), np.array([s_ddot]))
        except ValueError:
            pass
        else:  # pragma: no cover - the vectors would be wrong
            raise AssertionError(f"the Python model accepts the invalid case {spec}")
        out.append({"model": 0, "mode": label, "alpha": [float(a) for a in alpha], "s_dot": [float(v) for v in s_dot],
                    "s_ddot": [float(v) for v in s_ddot], "status": status})
    return out


def vectors() -> dict[str, Any]:
    rng = np.random.default_rng(SEED)
    models = vehicles(rng)
    return {
        "description": "C++ feed-forward (cpp/) against the Python reference agvdyn.dynamics.feedforward_torques, "
                       "eq. (21); generated by cpp/tests/make_vectors.py, read by ff_tests and "
                       "tests/test_cpp_feedforward.py",
        "tolerance": {"relative": RELATIVE, "absolute": ABSOLUTE,
                      "rule": "|u - u_ref| <= relative * max|u_ref| + absolute per case; the same for q_dot, q_ddot"},
        "settings": {"epsilon": EPSILON, "mode_tolerance": MODE_TOLERANCE, "stop_tolerance": STOP_TOLERANCE},
        "parameter_names": list(PARAMETER_NAMES),
        "models": [{"name": name, "geometry": {k: getattr(g, k) for k in ("l", "b", "a", "r", "i_G")},
                    "parameters": p.to_dict()} for name, g, p in models],
        "cases": valid_cases(models, rng),
        "invalid": invalid_cases(models),
    }


def to_text(data: dict[str, Any]) -> str:
    """JSON with one case per line (diff-friendly); NaN and infinity as Python's json writes them."""
    lines = ["{"]
    keys = list(data)
    for i, key in enumerate(keys):
        end = "," if i < len(keys) - 1 else ""
        value = data[key]
        if isinstance(value, list) and value and isinstance(value[0], dict):
            items = [" " * 2 + json.dumps(v) for v in value]
            lines.append(f" {json.dumps(key)}: [\n" + ",\n".join(items) + f"\n ]{end}")
        else:
            lines.append(f" {json.dumps(key)}: {json.dumps(value)}{end}")
    return "\n".join(lines) + "\n}\n"


def write_example_data() -> None:
    """Inputs of the ctest of the example control loop: a parameter file as ``agvdyn identify`` writes
    it, a platform file, and 20-row windows of ``agvdyn feedforward`` tables in every mode."""
    import pandas as pd

    from agvdyn.platform import ParameterFile, PAPER_STD, write_parameters, write_platform
    from agvdyn.simulation import feedforward_table

    DATA.mkdir(exist_ok=True)
    write_parameters(DATA / "params.yaml", ParameterFile(PAPER_PARAMETERS, dict(PAPER_STD), ("B_w",), 11.56,
                                                         geometry=PROTOTYPE))
    write_platform(DATA / "platform.yaml", Geometry(l=1.0, b=0.7, a=0.04, r=0.09, i_G=20.0, name="small"))
    windows = []
    for experiment, picks in (("identification", ("steer_left", "straight", "rotation", "align")),
                              ("lane-change", ("lane_change",)), ("lateral", ("lateral",))):
        table = feedforward_table(experiment, PAPER_PARAMETERS, PROTOTYPE)
        for segment in picks:
            moving = (table["segment"] == segment) & (table[["alpha_l_dot", "v_x", "v_y", "omega"]].abs().max(axis=1) > 0.05)
            rows = table.index[moving]
            mid = rows[int(len(rows) * 0.41)]
            windows.append(table.loc[mid:mid + 19])
    pd.concat(windows).to_csv(DATA / "feedforward_short.csv", index=False)


def main() -> int:
    PATH.write_text(to_text(vectors()), encoding="utf-8")
    print(f"wrote {PATH}")
    write_example_data()
    print(f"wrote {DATA}/params.yaml, platform.yaml, feedforward_short.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
