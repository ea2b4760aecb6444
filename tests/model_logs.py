"""Exact model data in the log schema, generated from the core (kinematics + dynamics).

Shared by tests/test_identification.py, tests/test_validation.py, tests/test_report.py and
benchmarks/bench_identification.py. Each segment moves one generalized coordinate along
``s(t) = sum_k a_k (sin(k w t) - k sin(w t))``, ``w = 2 pi / T``: position, velocity and
acceleration are analytic and velocity and acceleration are zero at both ends (start and
stop at rest). Joint velocities come from ``kinematics.joint_motion``; since H_k is constant
in modes 1, 3, 4 and straight the joint angles are ``H_k s`` exactly; torques from
``dynamics.feedforward_torques`` with the true parameters.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from agvdyn.dynamics import feedforward_torques
from agvdyn.kinematics import Mode, joint_motion, kinematic_model, nominal_steering, steering_from_virtual
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, Geometry, Parameters

#: (segment, mode, amplitudes a_k for k = 2, 3, ... of each generalized coordinate)
SEGMENTS = {
    "steer_left": (Mode.PARKING, [(0.25, -0.12, 0.06), (0.0,)]),
    "steer_right": (Mode.PARKING, [(0.0,), (-0.22, 0.1, -0.07)]),
    "straight": (Mode.STRAIGHT, [(0.9, -0.5, 0.25)]),
    "rotation": (Mode.ROTATION, [(0.5, 0.3, -0.2)]),
    "lateral": (Mode.LATERAL, [(0.6, -0.3, 0.2)]),
}


def fourier_motion(t: np.ndarray, period: float, amplitudes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, s_dot, s_ddot) of ``sum_k a_k (sin(k w t) - k sin(w t))``, k = 2, 3, ..."""
    w = 2 * math.pi / period
    s = np.zeros_like(t)
    sd = np.zeros_like(t)
    sdd = np.zeros_like(t)
    for k, a in enumerate(amplitudes, start=2):
        s += a * (np.sin(k * w * t) - k * np.sin(w * t))
        sd += a * k * w * (np.cos(k * w * t) - np.cos(w * t))
        sdd += a * w**2 * (-(k**2) * np.sin(k * w * t) + k * np.sin(w * t))
    return s, sd, sdd


def segment_frame(name: str, duration: float, *, geometry: Geometry = PROTOTYPE,
                  params: Parameters = PAPER_PARAMETERS, dt: float = 2e-3, t0: float = 0.0,
                  beta0: np.ndarray | None = None, repeats: int = 1) -> tuple[pd.DataFrame, dict]:
    """One segment as a log frame (t, alpha, beta, m, segment) plus the exact signals."""
    mode, amps = SEGMENTS[name]
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    period = duration / repeats
    parts = [fourier_motion(t, period, a) for a in amps]
    s = np.stack([p[0] for p in parts], axis=1)
    s_dot = np.stack([p[1] for p in parts], axis=1)
    s_ddot = np.stack([p[2] for p in parts], axis=1)
    if mode is Mode.PARKING:
        alpha = s.copy()
    else:
        alpha = np.broadcast_to(nominal_steering(geometry, mode), (n, 2)).copy()
    H = kinematic_model(geometry, mode, alpha)
    q_dot, q_ddot = joint_motion(geometry, mode, alpha, s_dot, s_ddot)
    beta = np.einsum("nij,nj->ni", H[:, 5:, :], s)  # H_k constant: q = H_k s
    if beta0 is not None:
        beta = beta + beta0
    u = feedforward_torques(geometry, params, mode, alpha, s_dot, s_ddot)
    frame = _frame(t0 + t, alpha, beta, u, name)
    exact = {"mode": mode, "alpha": alpha, "q_dot": q_dot, "q_ddot": q_ddot, "u": u, "s_dot": s_dot, "t": t0 + t}
    return frame, exact


def lane_change_frame(duration: float = 12.0, *, geometry: Geometry = PROTOTYPE,
                      params: Parameters = PAPER_PARAMETERS, dt: float = 2e-3, t0: float = 0.0
                      ) -> tuple[pd.DataFrame, dict]:
    """A lane change in the car-like mode 2: alpha_v(t) one sine period, forward speed bell-shaped.

    Mode 2's H depends on alpha, so the wheel angles are integrated numerically (cumulative
    trapezoid on a 10x finer grid); only the exact signals are needed by the validation tests.
    """
    n = int(round(duration / dt))
    fine = 10
    tf = np.arange(n * fine) * (dt / fine)
    w = 2 * math.pi / duration
    # alpha_v = A sin^3(w t / 2) cos(w t / 2) style: zero with zero rate at both ends
    A = 0.25
    av = A * np.sin(w * tf) * np.sin(w * tf / 2) ** 2
    av_d = A * (w * np.cos(w * tf) * np.sin(w * tf / 2) ** 2 + np.sin(w * tf) * w * np.sin(w * tf / 2) * np.cos(w * tf / 2))
    av_dd = np.gradient(av_d, tf, edge_order=2)
    vmax = 1.2
    vx = vmax * np.sin(w * tf / 2) ** 2
    vx_d = vmax * w * np.sin(w * tf / 2) * np.cos(w * tf / 2)
    s_dot = np.stack([av_d, vx], axis=1)
    s_ddot = np.stack([av_dd, vx_d], axis=1)
    alpha = steering_from_virtual(geometry, av)
    q_dot, q_ddot = joint_motion(geometry, Mode.CAR_LIKE, alpha, s_dot, s_ddot)
    beta = np.concatenate([np.zeros((1, 4)), np.cumsum((q_dot[1:, 5:] + q_dot[:-1, 5:]) / 2 * (dt / fine), axis=0)])
    u = feedforward_torques(geometry, params, Mode.CAR_LIKE, alpha, s_dot, s_ddot)
    sl = slice(None, None, fine)
    frame = _frame(t0 + tf[sl], alpha[sl], beta[sl], u[sl], "lane_change")
    exact = {"mode": Mode.CAR_LIKE, "alpha": alpha[sl], "q_dot": q_dot[sl], "q_ddot": q_ddot[sl], "u": u[sl],
             "s_dot": s_dot[sl], "t": t0 + tf[sl]}
    return frame, exact


def align_frame(alpha0, alpha1, duration: float = 2.0, *, geometry: Geometry = PROTOTYPE,
                params: Parameters = PAPER_PARAMETERS, dt: float = 2e-3, t0: float = 0.0,
                beta0: np.ndarray | None = None) -> tuple[pd.DataFrame, dict]:
    """Wheel alignment at rest (mode 1) from alpha0 to alpha1 along a quintic (rest to rest)."""
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    x = t / duration
    d = np.asarray(alpha1, dtype=float) - np.asarray(alpha0, dtype=float)
    shape = 10 * x**3 - 15 * x**4 + 6 * x**5
    shape_d = (30 * x**2 - 60 * x**3 + 30 * x**4) / duration
    shape_dd = (60 * x - 180 * x**2 + 120 * x**3) / duration**2
    alpha = np.asarray(alpha0, dtype=float) + shape[:, None] * d
    s_dot, s_ddot = shape_d[:, None] * d, shape_dd[:, None] * d
    H = kinematic_model(geometry, Mode.PARKING, alpha)
    q_dot, q_ddot = joint_motion(geometry, Mode.PARKING, alpha, s_dot, s_ddot)
    beta = np.einsum("nij,nj->ni", H[:, 5:, :], alpha - np.asarray(alpha0, dtype=float))
    if beta0 is not None:
        beta = beta + beta0
    u = feedforward_torques(geometry, params, Mode.PARKING, alpha, s_dot, s_ddot)
    exact = {"mode": Mode.PARKING, "alpha": alpha, "q_dot": q_dot, "q_ddot": q_ddot, "u": u, "s_dot": s_dot,
             "t": t0 + t}
    return _frame(t0 + t, alpha, beta, u, "align"), exact


def _frame(t, alpha, beta, u, name) -> pd.DataFrame:
    data = {"t": t, "alpha_l": alpha[:, 0], "alpha_r": alpha[:, 1]}
    for i, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"beta_{w}"] = beta[:, i]
    for i, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"m_{w}"] = u[:, i]
    data["segment"] = name
    return pd.DataFrame(data)


def identification_frame(durations: dict[str, float] | None = None, *, geometry: Geometry = PROTOTYPE,
                         params: Parameters = PAPER_PARAMETERS, dt: float = 2e-3, repeats: int = 1,
                         align: float = 0.0) -> tuple[pd.DataFrame, list[dict]]:
    """The paper's identification sequence (steer_left, steer_right, straight, rotation) in one frame.

    ``align > 0``: an ``align`` segment of that duration (s) steers the wheels at rest between two
    experiments whose steering angles differ, so that the angles are continuous (a real log).
    """
    durations = durations or {"steer_left": 20.0, "steer_right": 20.0, "straight": 20.0, "rotation": 20.0}
    frames, exact = [], []
    t0 = 0.0
    beta0 = np.zeros(4)
    alpha_end = np.zeros(2)

    def add(frame, ex):
        nonlocal t0, beta0, alpha_end
        frames.append(frame)
        exact.append(ex)
        t0 = float(frame["t"].iloc[-1]) + dt
        beta0 = frame[["beta_fl", "beta_rl", "beta_fr", "beta_rr"]].to_numpy()[-1]
        alpha_end = frame[["alpha_l", "alpha_r"]].to_numpy()[-1]

    for name, duration in durations.items():
        frame, ex = segment_frame(name, duration, geometry=geometry, params=params, dt=dt, t0=t0, beta0=beta0,
                                  repeats=repeats)
        start = frame[["alpha_l", "alpha_r"]].to_numpy()[0]
        if align and frames and np.max(np.abs(start - alpha_end)) > 0:
            add(*align_frame(alpha_end, start, align, geometry=geometry, params=params, dt=dt, t0=t0, beta0=beta0))
            frame, ex = segment_frame(name, duration, geometry=geometry, params=params, dt=dt, t0=t0,
                                      beta0=beta0, repeats=repeats)
        add(frame, ex)
    return pd.concat(frames, ignore_index=True), exact


def offset_blocks(y_c: float, *, geometry: Geometry = PROTOTYPE, params: Parameters = PAPER_PARAMETERS,
                  durations: dict[str, float] | None = None, lane_s: float = 12.0) -> list:
    """Exact equation blocks (model ``com_offset``) of the paper's sequence plus a lane change, with a chassis
    centre of mass at ``(0, y_c)``: the torques of eq. (19) plus ``m_ch y_c`` times its column
    (:func:`agvdyn.dynamics_extended.com_offset_forces`, projected). Only the car-like rows see ``y_c``."""
    import dataclasses

    from agvdyn.identification import equation_block
    from agvdyn.model_spec import ModelSpec

    durations = durations or {"steer_left": 6.0, "steer_right": 6.0, "straight": 6.0, "rotation": 6.0}
    _, exact = identification_frame(durations, geometry=geometry, params=params)
    t_end = float(exact[-1]["t"][-1])
    exact.append(lane_change_frame(lane_s, geometry=geometry, params=params, t0=t_end + 2e-3)[1])
    names = list(durations) + ["lane_change"]
    model = ModelSpec(com_offset=True)
    first_moments = np.array([0.0, params.m_ch * y_c])
    out = []
    for name, e in zip(names, exact):
        b = equation_block(geometry, e["mode"], e["alpha"], e["q_dot"], e["q_ddot"], e["u"], t=e["t"],
                           segment=name, source="exact", model=model)
        out.append(dataclasses.replace(b, torque=b.torque + b.model_regressor @ first_moments))
    return out
