"""The "real vehicle": rigid-body dynamics with tyre slip instead of rolling constraints.

This is NOT the identification model. Nine generalized velocities (PLATFORM.md)
``v = (v_x, v_y, omega, alpha_l_dot, alpha_r_dot, beta_fl_dot, beta_rl_dot, beta_fr_dot, beta_rr_dot)``
(body-frame chassis velocities) and nine positions ``(X, Y, gamma, alpha_l, alpha_r, beta_*)``
(world pose). The eight rolling constraints ``A(alpha) v = 0`` of eq. (1)-(2) are replaced by
tyre forces on the slip velocities ``A(alpha) v`` (lateral and longitudinal slip of each contact
point): ``F = -mu F_z tanh(|sigma|) sigma / |sigma|`` with ``sigma = (C_lat s_lat, C_long s_long) /
(V mu F_z)``, where ``C_*`` are slip stiffnesses (N per unit slip) and ``V = max(|r beta_dot|,
|v_contact|, v_0)`` the rolling speed regularised at ``v_0`` (a linear damper near standstill).
Steering is passive: only the longitudinal tyre forces acting at the offset ``a`` turn it.

Mass matrix: with the neglected effects off, ``M = diag(m_ch, m_ch, C_ch + C_l + C_r, C_l, C_r, B_w I_4)``
and the Coriolis terms of eq. (16), i.e. exactly the identification model's inertia. Switching
``steering_masses`` on places four steering units of mass ``unit_mass`` with their centre of mass
at ``unit_offset`` from the steering axis along the axle (where the wheel is); the chassis body
keeps the rest, so that total mass and yaw inertia at alpha = 0 still equal ``m_ch`` and
``C_ch + C_l + C_r``, but the inertia now depends on alpha and steering and chassis are coupled
(the gyroscopic/Coriolis terms the paper neglects, sec. 4).

Integration (why): the tyres make the system stiff (a wheel's reflected inertia ``B_w/r^2 = 12 kg``
against a slip damping of ``C/v_0 ~ 1e6 N s/m`` has a time constant of ~10 us). Every dissipative
force is linear in the velocities with a coefficient that depends on the state (tyre secant
``F/s``, viscous friction, the secant of Coulomb friction), so one linearly-implicit (semi-implicit)
Euler step solves ``(M + dt D(x_n)) v_{n+1} = M v_n + dt (B u - h(x_n, v_n) + f_stops)`` and then
``x_{n+1} = x_n + dt v_{n+1}``. It is unconditionally stable for the stiff part, and as the
slip stiffness grows the step becomes the M-orthogonal projection onto ``A v = 0``, i.e. the
rolling-constraint model: the convergence test measures it. The step is ``T_s / substeps``
(default 0.5 ms) for accuracy of the explicit Coriolis terms and of the lagged secants.

Coulomb friction with stiction: ``tau = -level(|v|) v / max(|v|, v_stick)``, implicit, with
``v_stick = 1e-4 rad/s`` and ``level = d_c (1 + (ratio - 1) exp(-(v / v_stribeck)^2))``. Below the
breakaway torque ``ratio d_c`` the joint sticks: its velocity stays below ``v_stick tau / (ratio d_c)``
(creep of at most 1e-4 rad/s, a numerical regularisation 100 times narrower than the model's
tanh with epsilon = 0.01 rad/s, which creeps at up to 0.01 rad/s under any torque); above it
the joint breaks away and slides with ``d_c sign(v)``. ``coulomb="tanh"`` uses the
identification model's ``d_c tanh(v / epsilon)`` instead (for the convergence test).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit

from agvdyn.platform import EPSILON, Geometry, Parameters

GRAVITY = 9.81

# Indices of the constant vector handed to the compiled code.
(_L, _B, _A, _R, _IG, _MB, _CB, _MU_MASS, _EU, _JUL, _JUR, _BW, _DVL, _DCL, _DVR, _DCR, _DVW, _DCW,
 _CLONG, _CLAT, _MU, _FZ, _V0, _COUL, _VSTICK, _RATIO, _VSTRIB, _EPS, _TLIM, _KSTOP, _DSTOP, _NCONST) = range(32)

_COULOMB = {"stiction": 0.0, "tanh": 1.0, "none": 2.0}


@dataclass(frozen=True)
class PlantSettings:
    """Settings of the simulated vehicle beyond the 11 parameters of eq. (18).

    Tyres: ``slip_stiffness_long`` / ``slip_stiffness_lat`` (N per unit slip), friction coefficient
    ``mu``, standstill regularisation ``slip_velocity`` (m/s). Neglected effects, each switchable:
    ``coulomb`` friction model (``"stiction"`` true stick/slip, ``"tanh"`` the model's, ``"none"``),
    ``breakaway_ratio`` (static / sliding friction, Stribeck velocity ``stribeck_velocity``),
    ``steering_masses`` (unit masses ``unit_mass`` at ``unit_offset`` from the steering axis; None
    = the offset a), ``torque_limit`` (motor peak torque in N m; None = unlimited).
    Mechanical steering stops at +-pi/2: stiffness ``stop_stiffness``, damping ``stop_damping``.
    """

    slip_stiffness_long: float = 4.0e4
    slip_stiffness_lat: float = 3.0e4
    mu: float = 0.8
    slip_velocity: float = 0.02
    coulomb: Literal["stiction", "tanh", "none"] = "stiction"
    stick_velocity: float = 1e-4
    breakaway_ratio: float = 1.0
    stribeck_velocity: float = 0.01
    steering_masses: bool = True
    unit_mass: float = 30.0
    unit_offset: float | None = None
    torque_limit: float | None = 6.0
    stop_stiffness: float = 2.0e4
    stop_damping: float = 200.0
    substeps: int = 4

    def __post_init__(self) -> None:
        if self.coulomb not in _COULOMB:
            raise ValueError(f"coulomb={self.coulomb!r}: expected one of {sorted(_COULOMB)}")
        for key in ("slip_stiffness_long", "slip_stiffness_lat", "mu", "slip_velocity", "stick_velocity",
                    "stribeck_velocity", "stop_stiffness", "stop_damping"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"plant setting {key}={v!r}: expected a finite number > 0")
        if not self.breakaway_ratio >= 1:
            raise ValueError(f"breakaway_ratio={self.breakaway_ratio!r}: expected >= 1 (static >= sliding friction)")
        if not self.unit_mass >= 0:
            raise ValueError(f"unit_mass={self.unit_mass!r}: expected >= 0 kg")
        if self.torque_limit is not None and not self.torque_limit > 0:
            raise ValueError(f"torque_limit={self.torque_limit!r}: expected > 0 N m or None")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(f"substeps={self.substeps!r}: expected an integer >= 1")

    def ideal(self) -> "PlantSettings":
        """The same tyres with every neglected effect off (the identification model's structure)."""
        from dataclasses import replace
        return replace(self, coulomb="tanh", steering_masses=False, torque_limit=None)

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def plant_constants(geom: Geometry, params: Parameters, settings: PlantSettings) -> np.ndarray:
    """Constant vector of the compiled plant from geometry, true parameters (eq. 18) and settings."""
    c = np.zeros(_NCONST)
    c[_L], c[_B], c[_A], c[_R], c[_IG] = geom.l, geom.b, geom.a, geom.r, geom.i_G
    m_u = settings.unit_mass if settings.steering_masses else 0.0
    e_u = (geom.a if settings.unit_offset is None else settings.unit_offset) if settings.steering_masses else 0.0
    for key, C in ((_JUL, params.C_l), (_JUR, params.C_r)):
        c[key] = C / 2 - m_u * e_u**2
        if c[key] < 0:
            raise ValueError(f"steering units of {m_u} kg at {e_u} m have more inertia about the steering axis "
                             f"({m_u * e_u ** 2:.4g} kg m^2) than C/2 = {C / 2:.4g}: expected a smaller unit mass")
    c[_MU_MASS], c[_EU] = m_u, e_u
    c[_MB] = params.m_ch - 4 * m_u
    if c[_MB] <= 0:
        raise ValueError(f"unit_mass={m_u}: four units weigh more than m_ch={params.m_ch}")
    c[_BW], c[_DVL], c[_DCL], c[_DVR], c[_DCR] = params.B_w, params.d_vl, params.d_cl, params.d_vr, params.d_cr
    c[_DVW], c[_DCW] = params.d_vw, params.d_cw
    c[_CLONG], c[_CLAT], c[_MU] = settings.slip_stiffness_long, settings.slip_stiffness_lat, settings.mu
    c[_FZ] = params.m_ch * GRAVITY / 4
    c[_V0] = settings.slip_velocity
    c[_COUL] = _COULOMB[settings.coulomb]
    c[_VSTICK], c[_RATIO], c[_VSTRIB], c[_EPS] = (settings.stick_velocity, settings.breakaway_ratio,
                                                    settings.stribeck_velocity, EPSILON)
    c[_TLIM] = np.inf if settings.torque_limit is None else settings.torque_limit
    c[_KSTOP], c[_DSTOP] = settings.stop_stiffness, settings.stop_damping
    # chassis body inertia: total yaw inertia at alpha = 0 equals C_ch + C_l + C_r
    c[_CB] = 0.0
    M0 = np.zeros((9, 9))
    _mass_matrix(c, np.zeros(2), M0)
    c[_CB] = params.C_ch + params.C_l + params.C_r - M0[2, 2]
    return c


@njit(cache=True)
def _unit_geometry(c, alpha, i):
    """Heading, side sign, heading sign, steering axis and unit position terms of wheel i."""
    side = 0 if i < 2 else 1
    s = 1.0 if i < 2 else -1.0
    h = 1.0 if i % 2 == 0 else -1.0
    cx = c[_L] / 2 * h
    cy = c[_B] / 2 * s
    th = h * alpha[side]
    return side, s, h, cx, cy, th


@njit(cache=True)
def _mass_matrix(c, alpha, M):
    """Mass matrix M(alpha) (9, 9) of the plant (body-frame velocities)."""
    M[:, :] = 0.0
    M[0, 0] = c[_MB]
    M[1, 1] = c[_MB]
    M[2, 2] = c[_CB]
    m_u, e = c[_MU_MASS], c[_EU]
    J = np.zeros(9)
    for i in range(4):
        side, s, h, cx, cy, th = _unit_geometry(c, alpha, i)
        ct, st = math.cos(th), math.sin(th)
        px = cx - s * e * st
        py = cy + s * e * ct
        dpx = -s * e * h * ct  # d p / d alpha_side
        dpy = -s * e * h * st
        # translational Jacobian rows (x and y) restricted to the nonzero columns 0, 1, 2, 3 + side
        jx = (1.0, 0.0, -py, dpx)
        jy = (0.0, 1.0, px, dpy)
        idx = (0, 1, 2, 3 + side)
        for p in range(4):
            for q in range(4):
                M[idx[p], idx[q]] += m_u * (jx[p] * jx[q] + jy[p] * jy[q])
        Ju = c[_JUL] if side == 0 else c[_JUR]
        M[2, 2] += Ju
        M[3 + side, 3 + side] += Ju
        M[2, 3 + side] += Ju * h
        M[3 + side, 2] += Ju * h
    for i in range(4):
        M[5 + i, 5 + i] = c[_BW]
    return J


@njit(cache=True)
def _bias(c, alpha, v, out):
    """Coriolis and centrifugal forces h(alpha, v) (9,) of the plant in body-frame velocities."""
    out[:] = 0.0
    w = v[2]
    out[0] = -c[_MB] * w * v[1]
    out[1] = c[_MB] * w * v[0]
    m_u, e = c[_MU_MASS], c[_EU]
    if m_u == 0.0:
        return
    for i in range(4):
        side, s, h, cx, cy, th = _unit_geometry(c, alpha, i)
        ct, st = math.cos(th), math.sin(th)
        px = cx - s * e * st
        py = cy + s * e * ct
        dpx = -s * e * h * ct
        dpy = -s * e * h * st
        ad = v[3 + side]
        # velocity of the unit's centre of mass (body components)
        wx = v[0] - w * py + dpx * ad
        wy = v[1] + w * px + dpy * ad
        # J_dot v = omega z x p_dot + d2p/dalpha2 alpha_dot^2 ; d2p/dalpha2 = -s e (-sin, cos)
        pdx, pdy = dpx * ad, dpy * ad
        ax = -w * pdy + (s * e * st) * ad * ad - w * wy
        ay = w * pdx + (-s * e * ct) * ad * ad + w * wx
        out[0] += m_u * ax
        out[1] += m_u * ay
        out[2] += m_u * (-py * ax + px * ay)
        out[3 + side] += m_u * (dpx * ax + dpy * ay)


@njit(cache=True)
def _constraint_matrix(c, alpha, A):
    """A(alpha) (8, 9) of eq. (1)-(2): rows 0-3 lateral, 4-7 longitudinal slip of fl, rl, fr, rr."""
    A[:, :] = 0.0
    a, r = c[_A], c[_R]
    for i in range(4):
        side, s, h, cx, cy, th = _unit_geometry(c, alpha, i)
        ct, st = math.cos(th), math.sin(th)
        A[i, 0] = -st
        A[i, 1] = ct
        A[i, 2] = st * cy + ct * cx
        A[4 + i, 0] = ct
        A[4 + i, 1] = st
        A[4 + i, 2] = -ct * cy + st * cx - s * a
        A[4 + i, 3 + side] = -s * a * h
        A[4 + i, 5 + i] = -r


@njit(cache=True)
def _coulomb_secant(c, vel, d_c):
    """Secant coefficient tau / v of the Coulomb friction at velocity ``vel``."""
    mode = c[_COUL]
    av = abs(vel)
    if mode == 2.0:
        return 0.0
    if mode == 1.0:
        x = av / c[_EPS]
        return d_c / c[_EPS] if x < 1e-8 else d_c * math.tanh(x) / av
    level = d_c * (1.0 + (c[_RATIO] - 1.0) * math.exp(-(av / c[_VSTRIB]) ** 2))
    return level / max(av, c[_VSTICK])


@njit(cache=True)
def _cholesky_solve(K, rhs, n):
    """Solve K x = rhs in place (K symmetric positive definite, overwritten); returns x in rhs."""
    for j in range(n):
        d = K[j, j]
        for k in range(j):
            d -= K[j, k] * K[j, k]
        d = math.sqrt(d)
        K[j, j] = d
        for i in range(j + 1, n):
            t = K[i, j]
            for k in range(j):
                t -= K[i, k] * K[j, k]
            K[i, j] = t / d
    for i in range(n):
        t = rhs[i]
        for k in range(i):
            t -= K[i, k] * rhs[k]
        rhs[i] = t / K[i, i]
    for i in range(n - 1, -1, -1):
        t = rhs[i]
        for k in range(i + 1, n):
            t -= K[k, i] * rhs[k]
        rhs[i] = t / K[i, i]


@njit(cache=True)
def plant_step(c, pos, vel, torque, dt, work, M, A, K, h, rhs, slip, dvec):
    """Advance the plant by one linearly-implicit Euler step of length dt (in place).

    ``torque``: motor torques (4,) after the drive's limit; ``work`` (3,) accumulates
    (motor work, dissipated work, stop work) over the step, evaluated at the new velocities.
    """
    alpha = pos[3:5]
    _mass_matrix(c, alpha, M)
    _bias(c, alpha, vel, h)
    _constraint_matrix(c, alpha, A)
    # slip velocities and tyre secant coefficients (lagged)
    for j in range(8):
        t = 0.0
        for q in range(9):
            t += A[j, q] * vel[q]
        slip[j] = t
    mufz = c[_MU] * c[_FZ]
    for i in range(4):
        v_contact = slip[4 + i] + c[_R] * vel[5 + i]
        V = max(abs(c[_R] * vel[5 + i]), math.sqrt(v_contact**2 + slip[i] ** 2), c[_V0])
        d_lat, d_long = c[_CLAT] / V, c[_CLONG] / V
        sig = math.sqrt((d_lat * slip[i]) ** 2 + (d_long * slip[4 + i]) ** 2) / mufz
        g = 1.0 if sig < 1e-9 else math.tanh(sig) / sig
        dvec[i] = d_lat * g
        dvec[4 + i] = d_long * g
    # K = M + dt (A^T D A + joint damping)
    for p in range(9):
        for q in range(9):
            t = 0.0
            for j in range(8):
                t += A[j, p] * dvec[j] * A[j, q]
            K[p, q] = M[p, q] + dt * t
    joint_d = np.zeros(9)
    joint_d[3] = c[_DVL] + _coulomb_secant(c, vel[3], c[_DCL])
    joint_d[4] = c[_DVR] + _coulomb_secant(c, vel[4], c[_DCR])
    for i in range(4):
        joint_d[5 + i] = c[_DVW] + _coulomb_secant(c, vel[5 + i], c[_DCW])
    for q in range(3, 9):
        K[q, q] += dt * joint_d[q]
    # right-hand side M v - dt h + dt B u (+ stops)
    for p in range(9):
        t = 0.0
        for q in range(9):
            t += M[p, q] * vel[q]
        rhs[p] = t - dt * h[p]
    for i in range(4):
        rhs[5 + i] += dt * c[_IG] * torque[i]
    stop_k = np.zeros(2)
    stop_pen = np.zeros(2)
    for j in range(2):
        lim = 0.5 * math.pi
        pen = alpha[j] - lim if alpha[j] > lim else (alpha[j] + lim if alpha[j] < -lim else 0.0)
        if pen != 0.0:
            stop_k[j] = 1.0
            stop_pen[j] = pen
            K[3 + j, 3 + j] += dt * (c[_DSTOP] + dt * c[_KSTOP])
            rhs[3 + j] -= dt * c[_KSTOP] * pen
    _cholesky_solve(K, rhs, 9)
    # energy accounts at the new velocities
    p_motor = 0.0
    for i in range(4):
        p_motor += c[_IG] * torque[i] * rhs[5 + i]
    p_diss = 0.0
    for j in range(8):
        t = 0.0
        for q in range(9):
            t += A[j, q] * rhs[q]
        p_diss += dvec[j] * t * t
    for q in range(3, 9):
        p_diss += joint_d[q] * rhs[q] * rhs[q]
    p_stop = 0.0
    for j in range(2):
        if stop_k[j] != 0.0:
            p_stop -= (c[_KSTOP] * (stop_pen[j] + dt * rhs[3 + j]) + c[_DSTOP] * rhs[3 + j]) * rhs[3 + j]
    work[0] += dt * p_motor
    work[1] += dt * p_diss
    work[2] += dt * p_stop
    # positions (symplectic: with the new velocities)
    g0 = pos[2]
    cg, sg = math.cos(g0 + 0.5 * dt * rhs[2]), math.sin(g0 + 0.5 * dt * rhs[2])
    pos[0] += dt * (cg * rhs[0] - sg * rhs[1])
    pos[1] += dt * (sg * rhs[0] + cg * rhs[1])
    for q in range(2, 9):
        pos[q] += dt * rhs[q]
    for q in range(9):
        vel[q] = rhs[q]


@njit(cache=True)
def kinetic_energy(c, pos, vel, M):
    """Kinetic energy 0.5 v^T M(alpha) v of the plant, J."""
    _mass_matrix(c, pos[3:5], M)
    e = 0.0
    for p in range(9):
        for q in range(9):
            e += vel[p] * M[p, q] * vel[q]
    return 0.5 * e


@njit(cache=True)
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
    M = np.zeros((9, 9))
    A = np.zeros((8, 9))
    K = np.zeros((9, 9))
    h = np.zeros(9)
    rhs = np.zeros(9)
    slip = np.zeros(8)
    dvec = np.zeros(8)
    work = np.zeros(3)
    dt = dt_sample / substeps
    P[0] = pos
    V[0] = vel
    E[0] = kinetic_energy(c, pos, vel, M)
    tq = np.zeros(4)
    for k in range(n):
        for i in range(4):
            tq[i] = min(max(torques[k, i], -c[_TLIM]), c[_TLIM])
        for j in range(substeps):
            plant_step(c, pos, vel, tq, dt, work, M, A, K, h, rhs, slip, dvec)
        P[k + 1] = pos
        V[k + 1] = vel
        E[k + 1] = kinetic_energy(c, pos, vel, M)
        W[k + 1] = work
    return P, V, E, W
