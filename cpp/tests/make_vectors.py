"""Test vectors of the C++ feed-forward from the Python reference (STYLE.md rule 9).

Writes ``cpp/tests/vectors.json``: random configurations and desired motions per motion mode on
three vehicles, with the joint motion (eq. 4, 20) and the motor torques of eq. (21) that
``agvdyn.dynamics.feedforward_torques`` computes, plus invalid inputs and the error each must give;
and the same for models beyond the paper (issue 30, ``extended_models``, ``extended_cases``:
Stribeck friction per joint group, an off-centre centre of mass, a delay) from their own random
stream, so that the paper's vectors stay as they were.
The C++ tests (``ff_tests``, ctest) and the pytest suite (``tests/test_cpp_feedforward.py``) both
read this file. Regenerate after a change of the Python model::

    .venv/bin/python cpp/tests/make_vectors.py [--tracker | --feedforward]

Also the payload tracker's vectors (``--tracker`` alone): ``cpp/tests/tracker_vectors.json`` (settings,
events, final state) and ``cpp/tests/data/tracker_sequence.csv`` (per sample: the row the C++
``PayloadTracker::update`` takes and the outputs of the Python reference ``agvdyn.online.tracker``);
the same with the centre-of-mass offset in ``tracker_offset_vectors.json`` and
``data/tracker_offset_sequence.csv`` (rows with phi_y, outputs with y_c and its std).
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
from agvdyn.model_spec import ModelParameters, ModelSpec
from agvdyn.platform import EPSILON, PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Geometry, Parameters

PATH = Path(__file__).with_name("vectors.json")
TRACKER_PATH = Path(__file__).with_name("tracker_vectors.json")
DATA = Path(__file__).with_name("data")
TRACKER_SEQUENCE = DATA / "tracker_sequence.csv"
#: Columns of the tracker sequence: the inputs of PayloadTracker::update, then the Python outputs.
TRACKER_COLUMNS = ("log", "kind", "phi_m", "phi_C", "z", "m_ch", "C_ch", "m_ch_std", "C_ch_std", "nis", "event")
#: The same with the centre-of-mass offset (TrackerSettings(com_offset=True)).
TRACKER_OFFSET_PATH = Path(__file__).with_name("tracker_offset_vectors.json")
TRACKER_OFFSET_SEQUENCE = DATA / "tracker_offset_sequence.csv"
TRACKER_OFFSET_COLUMNS = ("log", "kind", "phi_m", "phi_C", "phi_y", "z", "m_ch", "C_ch", "m_ch_std", "C_ch_std",
                          "y_c", "y_c_std", "nis", "event")
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


def _mode_cases(index: int, geom, params, rng, slow: bool = False) -> list[dict[str, Any]]:
    """CASES_PER_MODE random setpoints of every mode with their motion and torques (``params``: Parameters
    or ModelParameters); ``slow``: joint rates scaled down to 1 % of the usual (the Stribeck range)."""
    cases = []
    for mode in Mode:
        alpha = configurations(geom, mode, CASES_PER_MODE, rng)
        s_dot, s_ddot = motions(mode, CASES_PER_MODE, rng)
        if slow:
            s_dot *= 10.0 ** rng.uniform(-2.0, 0.0, (CASES_PER_MODE, 1))
        u = feedforward_torques(geom, params, mode, alpha, s_dot, s_ddot)
        q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
        for j in range(CASES_PER_MODE):
            cases.append({"model": index, "mode": mode.label, "alpha": _floats(alpha[j]),
                          "s_dot": _floats(s_dot[j]), "s_ddot": _floats(s_ddot[j]),
                          "q_dot": _floats(q_dot[j]), "q_ddot": _floats(q_ddot[j]), "u": _floats(u[j])})
    return cases


def valid_cases(models, rng) -> list[dict[str, Any]]:
    return [c for index, (_, geom, params) in enumerate(models) for c in _mode_cases(index, geom, params, rng)]


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


#: Models beyond the paper: (vehicle index, spec, breakaway ratio d_s/d_c per group, w_s per group,
#: (x_c, y_c), delay_s). A ratio below 1 (d_s < d_c) is data the identification may find.
EXTENDED = (
    (0, ModelSpec(friction="stribeck"), (1.3, 1.5, 1.2), (0.05, 0.1, 0.02), None, 0.0),
    (0, ModelSpec(com_offset=True), None, None, (0.15, -0.1), 0.0),
    (1, ModelSpec(friction="stribeck", delay=0.006, com_offset=True), (1.4, 1.25, 1.3), (0.03, 0.08, 0.05),
     (-0.12, 0.2), 0.006),
    (2, ModelSpec(friction="stribeck", com_offset=True), (0.8, 1.1, 1.5), (0.2, 0.01, 0.1), (0.05, 0.04), 0.0),
)


def extended_models(models) -> list[tuple[int, ModelParameters]]:
    """The models of :data:`EXTENDED` on the vehicles ``models`` (their geometry and 11 parameters)."""
    out = []
    for index, spec, ratio, w_s, centre, delay in EXTENDED:
        p = models[index][2]
        extra = {}
        if spec.stribeck:
            for g, d_c, k, w in zip("lrw", (p.d_cl, p.d_cr, p.d_cw), ratio, w_s):
                extra[f"d_s{g}"], extra[f"w_s{g}"] = k * d_c, w
        if spec.com_offset:
            extra["x_c"], extra["y_c"] = centre
        out.append((index, ModelParameters(p, extra, delay, spec)))
    return out


def extended_cases(models, extended, rng) -> list[dict[str, Any]]:
    """Cases of every mode on each extended model; joint rates down to 1 % of the usual, through
    the Stribeck range."""
    return [c for index, (vehicle, model) in enumerate(extended)
            for c in _mode_cases(index, models[vehicle][1], model, rng, slow=True)]


def _extended_entry(vehicle: int, model: ModelParameters) -> dict[str, Any]:
    return {"vehicle": vehicle, "model": {"friction": model.spec.friction, "delay_s": model.delay_s,
                                          "com_offset": model.spec.com_offset}, "extra": dict(model.extra)}


def vectors() -> dict[str, Any]:
    data = paper_vectors()
    rng = np.random.default_rng(SEED + 30)  # issue 30: a stream of its own
    models = vehicles(np.random.default_rng(SEED))
    extended = extended_models(models)
    data["extended_models"] = [_extended_entry(vehicle, model) for vehicle, model in extended]
    data["extended_cases"] = extended_cases(models, extended, rng)
    return data


def paper_vectors() -> dict[str, Any]:
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


# --- the payload tracker (agvdyn.online.tracker; C++ agvdyn_ff::PayloadTracker) -------------------

#: Settings of TrackerSettings the vectors hold (the rest belong to the rows); the paper's vectors
#: without those of the centre-of-mass offset (they are as they were before it).
OFFSET_SETTINGS = ("com_offset", "offset_change", "offset_std", "offset_walk")


def _simulated_rows(duration: int, seed: int, payload: str, com_offset: bool):
    """The causal rows of a simulated ``driving`` run (our plant, prototype, Table 2) with ``payload``."""
    import subprocess
    import tempfile

    from agvdyn.io import load_log
    from agvdyn.online import TrackerSettings
    from agvdyn.online.rows import causal_rows
    from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "drive.parquet"
        subprocess.run([str(Path(sys.executable).with_name("agvdyn")), "simulate", "driving", "--duration", str(duration),
                        "--seed", str(seed), "--payload", payload, "--quiet", "--out", str(out)], check=True,
                       capture_output=True)
        log = load_log(out)
    rules = TrackerSettings().rules
    return causal_rows(log.t, log.alpha, log.beta, log.torque, PROTOTYPE, PAPER_PARAMETERS, rules=rules,
                       torque_lead=0.0, slip_threshold=TrackerSettings().slip_threshold, com_offset=com_offset)


def tracker_inputs() -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], float]:
    """The tracker's input rows, per log: (kind (N,), phi (N, 2), z (N,)), and dt. Log 0: the causal rows
    (agvdyn.online.rows) of a simulated warehouse drive (our plant, prototype, Table 2, seed 2) that
    picks up 300 kg (at (0.2, 0) m, C 60 kg m^2) at 5 s, samples without a row thinned to every 25th,
    the first 3,500; log 1: :func:`_synthetic_rows`."""
    rows = _simulated_rows(16, 2, "5:300:0.2,0:60", False)
    keep = np.flatnonzero((rows.kind > 0) | (np.arange(rows.n) % 25 == 0))[:3500]  # the step's detection: 1,889
    logs = [(rows.kind[keep].astype(np.int64), rows.phi[keep], rows.z[keep])]
    logs.append(_synthetic_rows(np.random.default_rng(SEED)))
    return logs, rows.dt


def tracker_offset_inputs() -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], float]:
    """The rows of the tracker with the centre-of-mass offset, phi (N, 3) = (phi_m, phi_C, phi_y). Log 0:
    the causal rows of a simulated drive (seed 3: a lane change from 7 s) that picks up 250 kg at (0, 0.2) m
    (C 50 kg m^2) at 4 s, samples without a row thinned to every 25th, the first 6,000; log 1: the
    synthetic rows of :func:`_synthetic_rows` with an m_ch y_c column in half of every x_ch run (its
    car-like part), m_ch y_c stepping from 0 to 40 kg m with the drop and C_ch's step doubled."""
    rows = _simulated_rows(24, 3, "4:250:0,0.2:50", True)
    keep = np.flatnonzero((rows.kind > 0) | (np.arange(rows.n) % 25 == 0))[:6000]
    logs = [(rows.kind[keep].astype(np.int64), rows.phi[keep], rows.z[keep])]
    kind, phi, z = _synthetic_rows(np.random.default_rng(SEED))
    i = np.arange(kind.size)
    turning = np.isin(kind, (1, 2)) & ((i // 150) % 2 == 1)  # the car-like part: every other 150 rows
    kind = np.where(turning, kind + 6, kind)  # its kinds: x_ch+- car-like
    phi_y = np.where(turning, 0.3 * np.cos(2 * np.pi * i / 300.0), 0.0)
    s_y = np.where(i >= 3200, 40.0, 0.0)  # with the drop (the second x_ch+ run)
    more_C = np.where(i >= 4600, 40.0, 0.0)  # C_ch's step doubled: an alarm of C_ch's CUSUM here too
    logs.append((kind, np.column_stack([phi, phi_y]), z + phi_y * s_y + phi[:, 1] * more_C))
    return logs, rows.dt


def _synthetic_rows(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Log 1: rows of the tracker's own model z = phi_m m + phi_C C + b_kind + AR(1) noise, in runs of
    every kind, with a drop of 300 kg at the second x_ch+ run and +40 kg m^2 of C_ch in the middle of
    the second gamma_ch+ run (negative signs, C_ch detection, every bias and noise class: the car-like
    x_ch rows at the end, four times noisier)."""
    runs = [(1, 400), (5, 2500), (2, 300), (3, 200), (6, 300), (1, 500), (5, 800), (4, 300), (7, 400), (8, 300)]
    kind = np.concatenate([np.full(n, k) for k, n in runs]).astype(np.int64)
    n = kind.size
    i = np.arange(n)
    wave = np.sin(2 * np.pi * i / 400.0 + rng.uniform(0, 2 * np.pi))
    coord = np.array([0, 1, 1, 2, 2, 3, 3, 1, 1])[kind]  # agvdyn.online.rows.COORDINATE_OF_KIND
    phi = np.zeros((n, 2))
    phi[:, 0] = np.where(coord == 1, 0.4 * wave, np.where(coord == 2, 0.3 * wave, 0.0))
    phi[:, 1] = np.where(coord == 3, 1.0 * wave, np.where(coord == 1, 0.05 * np.cos(2 * np.pi * i / 400.0), 0.0))
    starts = np.cumsum([0] + [r[1] for r in runs])
    m = np.where(i >= starts[5], 842.0684, 1142.0684)
    C = np.where(i >= starts[6] + 400, 326.6, 286.6)  # mid-run: after the drop's reset, C_ch is relearnt first
    bias = np.array([0.0, 3.0, -2.0, 1.5, -1.0, 0.8, -0.5, 3.0, -2.0])[kind]  # car-like: the x_ch biases
    e = rng.normal(0.0, 0.6, n) * np.where(kind >= 7, 4.0, 1.0)  # car-like rows: a noise class of their own
    noise = np.zeros(n)
    for k in range(1, n):
        noise[k] = 0.98 * noise[k - 1] + e[k]
    z = phi[:, 0] * m + phi[:, 1] * C + bias + noise
    kind[::97] = 0  # some samples without a row
    return kind, phi, z


def run_python_tracker(logs, dt: float, nominal, nominal_std, com_offset: bool = False):
    """The Python reference over the logs as agvdyn.online.track runs them (state carried, CUSUMs
    restarted per log): per-sample outputs (N, 6) = m_ch, C_ch, their stds, nis, event ((N, 8) with the
    offset: y_c and its std before nis); the events (log, parameter, sign, sample, start, before,
    before_var, after, after_var); the final state."""
    from agvdyn.online import _kernels as kern
    from agvdyn.online import TrackerSettings
    from agvdyn.online.tracker import TrackerState
    from agvdyn.platform import PAPER_PARAMETERS

    settings = TrackerSettings(com_offset=com_offset)
    params = PAPER_PARAMETERS.replace(m_ch=float(nominal[0]), C_ch=float(nominal[1]))
    state = TrackerState.initial(params, dict(zip(("m_ch", "C_ch"), nominal_std)), settings)
    k = settings.constants(np.asarray(nominal, dtype=float), dt)
    ns = settings.states
    outputs, events = [], []
    for index, (kind, phi, z) in enumerate(logs):
        n = kind.size
        state.g[:] = 0.0
        theta, var, nis = np.zeros((n, ns)), np.zeros((n, ns)), np.zeros(n)
        flag = np.zeros(n, dtype=np.int64)
        offset = np.zeros((n if com_offset else 0, 2))
        found = np.zeros((settings.max_events, kern.E_NCOLS))
        count = kern.track_rows(np.ascontiguousarray(phi), np.ascontiguousarray(z), kind, k, state.theta, state.P,
                                state.R, state.n_rows, state.g, state.Iw, state.bw, state.start, theta, var, nis,
                                flag, offset, found, 0)
        outputs.append(np.column_stack([theta[:, :2], np.sqrt(var[:, :2]), *([offset] if com_offset else []), nis, flag]))
        for e in found[:count]:
            events.append({"log": index, "parameter": int(e[kern.E_PARAM]), "sign": int(e[kern.E_SIGN]),
                           "sample": int(e[kern.E_K]), "start": int(e[kern.E_START]),
                           "before": float(e[kern.E_BEFORE]), "before_var": float(e[kern.E_BEFORE_VAR]),
                           "after": float(e[kern.E_AFTER]), "after_var": float(e[kern.E_AFTER_VAR])})
    final = {"theta": _floats(state.theta), "P": _floats(state.P), "R": _floats(state.R),
             "n_rows": _floats(state.n_rows), "g": _floats(state.g), "start": [int(v) for v in np.ravel(state.start)]}
    return np.concatenate(outputs), events, final


def tracker_vectors(com_offset: bool = False) -> tuple[dict[str, Any], list[list[float]]]:
    """The tracker's vectors (JSON part) and the per-sample table of cpp/tests/data/tracker_sequence.csv
    (with ``com_offset``: tracker_offset_vectors.json, data/tracker_offset_sequence.csv)."""
    from agvdyn.online import TrackerSettings
    from agvdyn.platform import PAPER_PARAMETERS, PAPER_STD

    logs, dt = tracker_offset_inputs() if com_offset else tracker_inputs()
    nominal = [PAPER_PARAMETERS.m_ch, PAPER_PARAMETERS.C_ch]
    nominal_std = [PAPER_STD["m_ch"], PAPER_STD["C_ch"]]
    outputs, events, final = run_python_tracker(logs, dt, nominal, nominal_std, com_offset)
    skip = ("rules", "slip_threshold", "max_events") + (() if com_offset else OFFSET_SETTINGS)
    settings = {k: v for k, v in TrackerSettings(com_offset=com_offset).__dict__.items() if k not in skip}
    if com_offset:
        description = ("C++ PayloadTracker with com_offset (cpp/) against the Python reference agvdyn.online.tracker on "
                       "one sequence of rows (phi_m, phi_C, phi_y) (log 0: a simulated drive picking up 250 kg at "
                       "(0, 0.2) m at 4 s, a lane change from 7 s; log 1: synthetic rows of every kind with an m_ch y_c "
                       "column in the x_ch rows, a drop, a C_ch step of +80 kg m^2 and m_ch y_c 0 -> 40 kg m); per-sample table in "
                       f"data/{TRACKER_OFFSET_SEQUENCE.name}; y_c from the start 0 with the prior std offset_std; "
                       "generated by cpp/tests/make_vectors.py, read by ff_tests and tests/test_online.py")
    else:
        description = ("C++ PayloadTracker (cpp/) against the Python reference agvdyn.online.tracker on one "
                       "sequence of rows (log 0: a simulated drive picking up 300 kg at 5 s; log 1: synthetic rows "
                       "of every kind with a drop and a C_ch step); per-sample table in data/tracker_sequence.csv; "
                       "generated by cpp/tests/make_vectors.py, read by ff_tests and tests/test_cpp_feedforward.py")
    data = {
        "description": description,
        "tolerance": {"relative": RELATIVE, "rule": "|x - x_ref| <= relative * max(|x_ref|, 1) for every output "
                      "(estimates, stds, nis, event values and variances, final state); NaN nis where the reference "
                      "has NaN; event flags, event samples, starts, signs exact"},
        "settings": settings, "nominal": nominal, "nominal_std": nominal_std, "dt": dt,
        "logs": [int(kind.size) for kind, _, _ in logs],
        "sequence": f"data/{(TRACKER_OFFSET_SEQUENCE if com_offset else TRACKER_SEQUENCE).name}",
        "events": events, "final": final,
    }
    table = []
    offset = 0
    for index, (kind, phi, z) in enumerate(logs):
        for j in range(kind.size):
            o = outputs[offset + j]
            table.append([index, int(kind[j]), *map(float, phi[j]), float(z[j]), *map(float, o[:-1]), int(o[-1])])
        offset += kind.size
    return data, table


def write_tracker_vectors() -> None:
    for com_offset in (False, True):
        data, table = tracker_vectors(com_offset)
        (TRACKER_OFFSET_PATH if com_offset else TRACKER_PATH).write_text(to_text(data), encoding="utf-8")
        DATA.mkdir(exist_ok=True)
        lines = [",".join(TRACKER_OFFSET_COLUMNS if com_offset else TRACKER_COLUMNS)]
        lines += [",".join(repr(v) if isinstance(v, float) else str(v) for v in row) for row in table]
        (TRACKER_OFFSET_SEQUENCE if com_offset else TRACKER_SEQUENCE).write_text("\n".join(lines) + "\n",
                                                                              encoding="utf-8")


def main() -> int:
    only = set(sys.argv[1:])  # --tracker or --feedforward: only that part
    if only - {"--tracker", "--feedforward"}:
        print("usage: make_vectors.py [--tracker | --feedforward]", file=sys.stderr)
        return 2
    if "--tracker" not in only or "--feedforward" in only:
        PATH.write_text(to_text(vectors()), encoding="utf-8")
        print(f"wrote {PATH}")
        write_example_data()
        print(f"wrote {DATA}/params.yaml, platform.yaml, feedforward_short.csv")
    if "--feedforward" not in only or "--tracker" in only:
        write_tracker_vectors()
        print(f"wrote {TRACKER_PATH}, {TRACKER_SEQUENCE}, {TRACKER_OFFSET_PATH}, {TRACKER_OFFSET_SEQUENCE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
