"""Compiled closed loop of the simulation (numba): sensors, controller and :func:`run_chunk`, which
runs whole chunks of samples (plant substeps included) without Python per sample; also the open
loop, the kinetic energy and the floor geometry of the slip scenario. The plant step itself is in
:mod:`._plant_kernels` (numba compiles it into these kernels; its cache is dropped here when that
file is newer, :mod:`agvdyn._numba_cache`). The physics and the design choices are documented in
plant.py, sensors.py and controller.py.
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn._numba_cache import drop_stale_cache
from agvdyn.simulation import _plant_kernels
from agvdyn.simulation._plant_kernels import (
    _A, _TLIM, _constraint_rows, _jit, _jit_borrow, _mass_matrix, _slip_velocities, _unit_frame, _unit_trig,
    plant_step, workspace,
)

drop_stale_cache(__file__, _plant_kernels.__file__)


@_jit
def kinetic_energy(c, pos, vel, M):
    """Kinetic energy 0.5 v^T M(alpha) v of the plant, J."""
    _mass_matrix(c, pos[3:5], M)
    e = 0.0
    for p in range(9):
        for q in range(9):
            e += vel[p] * M[p, q] * vel[q]
    return 0.5 * e


@_jit
def run_open_loop(c, pos0, vel0, torques, dt_sample, substeps):
    """Plant driven by given motor torques (N, 4), held over each sample.

    Returns positions (N+1, 9), velocities (N+1, 9), energy (N+1,), cumulative work (N+1, 3).
    """
    n = torques.shape[0]
    pos = pos0.copy()
    vel = vel0.copy()
    P = np.zeros((n + 1, 9))
    V = np.zeros((n + 1, 9))
    E = np.zeros(n + 1)
    W = np.zeros((n + 1, 3))
    M, K, A, h, rhs, slip, dvec, jf, tr = workspace()
    work = np.zeros(3)
    dt = dt_sample / substeps
    P[0] = pos
    V[0] = vel
    E[0] = kinetic_energy(c, pos, vel, M)
    tq = np.zeros(4)
    mu_w = np.ones(4)
    for k in range(n):
        for i in range(4):
            tq[i] = min(max(torques[k, i], -c[_TLIM]), c[_TLIM])
        for j in range(substeps):
            plant_step(c, pos, vel, tq, dt, work, mu_w, M, K, A, h, rhs, slip, dvec, jf, tr)
        P[k + 1] = pos
        V[k + 1] = vel
        E[k + 1] = kinetic_energy(c, pos, vel, M)
        W[k + 1] = work
    return P, V, E, W


# --- slip scenario (see slip.py) ---

@_jit_borrow
def _contact_xy(c, pos, cg, sg, ct, st, i):
    """World position (X, Y) of the contact point of wheel i, steering axis plus a along the axle,
    from cos and sin of the heading (cg, sg) and of the wheel's heading h_i alpha_side (ct, st)."""
    side, s, h, cx, cy = _unit_frame(c, i)
    px = cx - s * c[_A] * st
    py = cy + s * c[_A] * ct
    return pos[0] + cg * px - sg * py, pos[1] + sg * px + cg * py


@_jit_borrow
def _contact_xys(c, pos):
    """World positions ((X, Y),) * 4 of the four contact points (three sine/cosine pairs)."""
    cg, sg = math.cos(pos[2]), math.sin(pos[2])
    cl, sl, cr, sr = math.cos(pos[3]), math.sin(pos[3]), math.cos(pos[4]), math.sin(pos[4])
    return (_contact_xy(c, pos, cg, sg, cl, sl, 0), _contact_xy(c, pos, cg, sg, cl, -sl, 1),
            _contact_xy(c, pos, cg, sg, cr, sr, 2), _contact_xy(c, pos, cg, sg, cr, -sr, 3))


@_jit_borrow
def patch_factors(c, pos, t, patches, mu_w):
    """Factor on mu (4,) of each wheel at time t: the smallest ``mu_factor`` of the patches
    (rows x_min, x_max, y_min, y_max, t_start, t_end, mu_factor) holding its contact point, else 1."""
    for i in range(4):
        mu_w[i] = 1.0
    for p in range(patches.shape[0]):
        if not (t < patches[p, 4] or t >= patches[p, 5]):
            break
    else:
        return  # no patch at this time
    xy = _contact_xys(c, pos)
    for p in range(patches.shape[0]):
        if t < patches[p, 4] or t >= patches[p, 5]:
            continue
        for i in range(4):
            x, y = xy[i]
            if patches[p, 0] <= x < patches[p, 1] and patches[p, 2] <= y < patches[p, 3]:
                mu_w[i] = min(mu_w[i], patches[p, 6])


@_jit
def contact_points(c, positions):
    """World positions (N, 4, 2) of the contact points of the plant positions (N, 9)."""
    n = positions.shape[0]
    out = np.zeros((n, 4, 2))
    for k in range(n):
        xy = _contact_xys(c, positions[k])
        for i in range(4):
            out[k, i, 0], out[k, i, 1] = xy[i]
    return out


@_jit
def slip_speeds(c, positions, velocities):
    """Slip speed (N, 4), m/s, of each contact point: the norm of its lateral and longitudinal
    slip velocity (rows i and 4 + i of A(alpha) v with the true rolling radii)."""
    n = positions.shape[0]
    out = np.zeros((n, 4))
    A = np.zeros((8, 9))
    tr = np.zeros((4, 2))
    s = np.zeros(8)
    for k in range(n):
        _unit_trig(positions[k, 3], positions[k, 4], tr)
        _constraint_rows(c, tr, A)
        _slip_velocities(A, velocities[k], s)
        for i in range(4):
            out[k, i] = math.sqrt(s[i] * s[i] + s[4 + i] * s[4 + i])
    return out


# --- sensors (see sensors.py) ---

@_jit_borrow
def quantize(x, resolution):
    """Reading of an incremental/absolute encoder: x rounded down to whole counts of ``resolution``."""
    return math.floor(x / resolution) * resolution


@_jit_borrow
def read_sensors(pos, k, wheel_res, steer_res, steer_noise, alpha_m, beta_m):
    """Measured steering angles (2,) and wheel angles (4,) of the plant positions ``pos`` at sample k.

    Steering angles are clipped to the calibrated range [-pi/2, pi/2] of the sensor (the stops).
    """
    lim = 0.5 * math.pi
    for j in range(2):
        a = quantize(pos[3 + j] + steer_noise[k, j] + 0.5 * steer_res, steer_res)
        alpha_m[j] = min(max(a, -lim), lim)
    for i in range(4):
        beta_m[i] = quantize(pos[5 + i], wheel_res)


# --- controller (see controller.py) ---

@_jit_borrow
def controller_step(g, Ts, k, alpha_m, beta_m, u_ff, mode_d, alpha_d, alpha_dot_d, beta_d, beta_dot_d, state, u):
    """Motor torque commands u (4,) at sample k from the measurements and the plan (in place)."""
    if state[12] == 0.0:
        for i in range(4):
            state[i] = beta_m[i]
        for j in range(2):
            state[4 + j] = alpha_m[j]
        state[12] = 1.0
    cw = Ts / (g[4] + Ts)
    cs = Ts / (g[5] + Ts)
    for i in range(4):
        state[6 + i] += cw * ((beta_m[i] - state[i]) / Ts - state[6 + i])
        state[i] = beta_m[i]
    for j in range(2):
        state[10 + j] += cs * ((alpha_m[j] - state[4 + j]) / Ts - state[10 + j])
        state[4 + j] = alpha_m[j]
    for i in range(4):
        u[i] = u_ff[k, i]
    if g[7] == 0.0:
        return
    lateral = mode_d[k] == 3
    lim = 0.5 * math.pi - 0.3
    near_lateral = lateral or (mode_d[k] == 1 and abs(alpha_d[k, 0]) > lim and abs(alpha_d[k, 1]) > lim)
    if k == 0 or mode_d[k] != mode_d[k - 1]:
        # mode switch: the wheel-angle references restart from the measured angles (the errors of
        # the previous mode, e.g. a steering-wheel difference from slip while driving, are dropped)
        for i in range(4):
            state[15 + i] = beta_m[i] - beta_d[k, i]
    ra = g[11]  # a / r
    for j in range(2):
        s = 1.0 if j == 0 else -1.0
        e_f = beta_d[k, 2 * j] + state[15 + 2 * j] - beta_m[2 * j]
        e_r = beta_d[k, 2 * j + 1] + state[16 + 2 * j] - beta_m[2 * j + 1]
        v_f = beta_dot_d[k, 2 * j] - state[6 + 2 * j]
        v_r = beta_dot_d[k, 2 * j + 1] - state[7 + 2 * j]
        e_c, e_d = 0.5 * (e_f + e_r), 0.5 * (e_f - e_r)
        v_c, v_d = 0.5 * (v_f + v_r), 0.5 * (v_f - v_r)
        if near_lateral:
            # keep the part of the front-rear difference that the steering does not explain
            # (beta_f - beta_r = -2 s a alpha / r at rest): lateral motion of the chassis
            e_d += s * ra * (alpha_d[k, j] - alpha_m[j])
            v_d += s * ra * (alpha_dot_d[k, j] - state[10 + j])
        else:  # the difference is the steering (slip makes it disagree): left to the steering loop
            e_d = 0.0
            v_d = 0.0
        u[2 * j] += g[0] * (v_c + v_d) + g[1] * (e_c + e_d)
        u[2 * j + 1] += g[0] * (v_c - v_d) + g[1] * (e_c - e_d)
    for j in range(2):
        e = alpha_d[k, j] - alpha_m[j]
        if lateral:
            # the steering rests on its stop, where pushing it means pushing the chassis sideways
            # (mode 3: steering torque = a F_y of the side): no integral part
            state[13 + j] = 0.0
        else:  # integral part, clamped (anti-windup)
            e_i = e - g[10] if e > g[10] else (e + g[10] if e < -g[10] else 0.0)  # dead band
            state[13 + j] = min(max(state[13 + j] + g[8] * e_i * Ts, -g[9]), g[9])
        ts = g[2] * e + g[3] * (alpha_dot_d[k, j] - state[10 + j]) + state[13 + j]
        dm = ts * g[6]
        s = 1.0 if j == 0 else -1.0
        u[2 * j] += -s * dm      # front wheel of the side (h = +1)
        u[2 * j + 1] += s * dm   # rear wheel (h = -1)


# --- closed loop ---

@_jit_borrow
def drive_sample(k, pos, vel, work, g, Ts, wheel_res, steer_res, u_ff, mode_d, alpha_d, alpha_dot_d, beta_d,
                 beta_dot_d, steer_noise, torque_noise, torque_offset, burst, lim, cstate, alpha_m, beta_m, u, ua, meas,
                 out_pos, out_vel, out_alpha, out_beta, out_cmd, out_app, out_meas, out_work):
    """Everything of sample k but the plant (shared by every plant, see :mod:`.mujoco_plant`): the
    sensors read the plant positions ``pos`` (``alpha_m``, ``beta_m``), the controller gives the
    commands ``u``, the drive limits them to ``lim`` and adds the burst (``ua``, what the motors
    apply), the torque sensors measure ``meas``; the sample (plant state ``pos``, ``vel``, ``work``
    at its start, sensors, torques) is recorded in row k of the ``out_*`` arrays."""
    read_sensors(pos, k, wheel_res, steer_res, steer_noise, alpha_m, beta_m)
    controller_step(g, Ts, k, alpha_m, beta_m, u_ff, mode_d, alpha_d, alpha_dot_d, beta_d, beta_dot_d, cstate, u)
    for i in range(4):
        ua[i] = min(max(u[i], -lim), lim)
        if burst[k, i] != 0.0:
            ua[i] += burst[k, i]
        meas[i] = ua[i] + torque_offset[i] + torque_noise[k, i]
    for i in range(pos.size):  # element by element: this kernel borrows its arrays (no NRT)
        out_pos[k, i] = pos[i]
        out_vel[k, i] = vel[i]
    for i in range(work.size):
        out_work[k, i] = work[i]
    out_alpha[k, 0], out_alpha[k, 1] = alpha_m[0], alpha_m[1]
    for i in range(4):
        out_beta[k, i] = beta_m[i]
        out_cmd[k, i] = u[i]
        out_app[k, i] = ua[i]
        out_meas[k, i] = meas[i]


@_jit
def run_chunk(k0, k1, c, g, Ts, substeps, wheel_res, steer_res,
              u_ff, mode_d, alpha_d, alpha_dot_d, beta_d, beta_dot_d, steer_noise, torque_noise, torque_offset,
              t, burst, patches,
              pos, vel, cstate, work,
              out_pos, out_vel, out_alpha, out_beta, out_cmd, out_app, out_meas, out_energy, out_work):
    """Simulate samples k0..k1-1 in place; ``pos``, ``vel``, ``cstate``, ``work`` carry the state.

    Slip scenario: ``burst`` (N, 4) motor torques added after the torque limit (the controller does
    not know them, the torque sensors measure them); ``patches`` (P, 7) floor patches of reduced
    mu (see :func:`patch_factors`) at the sample times ``t`` (N,) plus the substep offsets.
    """
    M, K, A, h, rhs, slip, dvec, jf, tr = workspace()
    alpha_m = np.zeros(2)
    beta_m = np.zeros(4)
    u = np.zeros(4)
    ua = np.zeros(4)
    mu_w = np.ones(4)
    dt = Ts / substeps
    lim = c[_TLIM]
    n_patches = patches.shape[0]
    meas = np.zeros(4)
    for k in range(k0, k1):
        drive_sample(k, pos, vel, work, g, Ts, wheel_res, steer_res, u_ff, mode_d, alpha_d, alpha_dot_d, beta_d,
                     beta_dot_d, steer_noise, torque_noise, torque_offset, burst, lim, cstate, alpha_m, beta_m, u, ua,
                     meas, out_pos, out_vel, out_alpha, out_beta, out_cmd, out_app, out_meas, out_work)
        for j in range(substeps):
            if n_patches > 0:
                patch_factors(c, pos, t[k] + j * dt, patches, mu_w)
            e = plant_step(c, pos, vel, ua, dt, work, mu_w, M, K, A, h, rhs, slip, dvec, jf, tr)
            if j == 0:  # the energy at the sample, from the step's M(alpha)
                out_energy[k] = e
