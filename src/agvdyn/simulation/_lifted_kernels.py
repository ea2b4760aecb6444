"""Compiled loop of the lifted-wheel experiment (sec. 7): wheels off the ground, each driven by its
speed loop; the plant constants and friction are those of :mod:`._plant_kernels`, the sensors those of :mod:`._kernels`."""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit
from agvdyn._numba_cache import drop_stale_cache
from agvdyn.simulation import _kernels, _plant_kernels
from agvdyn.simulation._kernels import read_sensors
from agvdyn.simulation._plant_kernels import _BW, _DCW, _DVW, _GROUP_W, _IG, _TLIM, _friction_terms, secant_damping

drop_stale_cache(__file__, _kernels.__file__, _plant_kernels.__file__)


@njit(cache=True)
def lifted_drive_sample(k, c, g, Ts, wheel_res, steer_res, u_ff, beta_d, beta_dot_d, steer_noise, torque_noise,
                        torque_offset, pos, vel, cstate, work, alpha_m, beta_m, u, ua,
                        out_pos, out_vel, out_alpha, out_beta, out_cmd, out_app, out_meas, out_work):
    """Sample k of the lifted-wheel drive, in place: sensors, a wheel speed loop per wheel on the
    feed-forward ``u_ff`` (gains of the controller's wheel loops, on the filtered encoder rate and
    the wheel angle), the motor torques ``ua`` limited to the torque limit; the outputs of sample k.
    Shared by our plant (:func:`run_lifted_chunk`) and MuJoCo's (``mujoco_lifted``). ``cstate``:
    previous encoder readings (4), filtered rates (4), started flag, angle reference offsets (4)."""
    cw = Ts / (g[4] + Ts)
    read_sensors(pos, k, wheel_res, steer_res, steer_noise, alpha_m, beta_m)
    if cstate[8] == 0.0:
        for i in range(4):
            cstate[i] = beta_m[i]
            cstate[9 + i] = beta_m[i] - beta_d[k, i]
        cstate[8] = 1.0
    for i in range(4):
        cstate[4 + i] += cw * ((beta_m[i] - cstate[i]) / Ts - cstate[4 + i])
        cstate[i] = beta_m[i]
        u[i] = u_ff[k, i]
        if g[7] != 0.0:
            u[i] += g[0] * (beta_dot_d[k, i] - cstate[4 + i]) + g[1] * (beta_d[k, i] + cstate[9 + i] - beta_m[i])
    out_pos[k] = pos
    out_vel[k] = vel
    out_alpha[k] = alpha_m
    out_beta[k] = beta_m
    out_work[k] = work
    lim = c[_TLIM]
    for i in range(4):
        ua[i] = min(max(u[i], -lim), lim)
        out_cmd[k, i] = u[i]
        out_app[k, i] = ua[i]
        out_meas[k, i] = ua[i] + torque_offset[i] + torque_noise[k, i]


@njit(cache=True)
def run_lifted_chunk(k0, k1, c, g, Ts, substeps, wheel_res, steer_res, u_ff, beta_d, beta_dot_d,
                     steer_noise, torque_noise, torque_offset, pos, vel, cstate, work,
                     out_pos, out_vel, out_alpha, out_beta, out_cmd, out_app, out_meas, out_energy, out_work):
    """Samples k0..k1-1 of the four wheels turning freely (no ground contact), in place.

    Each wheel: ``B_w beta_ddot = i_G M - d_vw beta_dot - F_c(beta_dot)`` with the plant's Coulomb
    friction (stiction by default), the same linearly-implicit step as the plant. Chassis and
    steering stand still. The drive: :func:`lifted_drive_sample`.
    """
    alpha_m = np.zeros(2)
    beta_m = np.zeros(4)
    u = np.zeros(4)
    ua = np.zeros(4)
    dt = Ts / substeps
    bw = c[_BW]
    for k in range(k0, k1):
        lifted_drive_sample(k, c, g, Ts, wheel_res, steer_res, u_ff, beta_d, beta_dot_d, steer_noise, torque_noise,
                            torque_offset, pos, vel, cstate, work, alpha_m, beta_m, u, ua,
                            out_pos, out_vel, out_alpha, out_beta, out_cmd, out_app, out_meas, out_work)
        e = 0.0
        for i in range(4):
            e += 0.5 * bw * vel[5 + i] ** 2
        out_energy[k] = e
        for i in range(4):
            for j in range(substeps):
                v = vel[5 + i]
                d, f0, tangent = _friction_terms(c, v, c[_DVW], c[_DCW], _GROUP_W, bw, dt)
                v_new = (bw * v + dt * (c[_IG] * ua[i] - f0)) / (bw + dt * d)
                if tangent and v_new * v < 0.0:  # the secant where the tangent reverses a slow wheel
                    d, f0 = secant_damping(c, v, c[_DVW], c[_DCW], _GROUP_W), 0.0
                    v_new = (bw * v + dt * c[_IG] * ua[i]) / (bw + dt * d)
                work[0] += dt * c[_IG] * ua[i] * v_new
                work[1] += dt * (d * v_new + f0) * v_new
                pos[5 + i] += dt * v_new
                vel[5 + i] = v_new
