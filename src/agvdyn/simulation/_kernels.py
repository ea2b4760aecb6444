"""Compiled kernels of the simulation (numba): plant step, sensors, controller step, closed loop.

They live in one module on purpose, hence its length: split into a plant module and a closed-loop
module (tried: run_chunk calling plant_step and the constraint helpers across files), the closed
loop ran 5-8 % slower (146-166 against 142-154 ms for the identification sequence, alternating
runs), which takes `simulate` below issue 12's 500x real time on this machine. (numba's cache
staleness across files is handled by :mod:`agvdyn._numba_cache` where kernels do call across files.)
The physics and the design choices are documented in plant.py, sensors.py and controller.py.

Speed (issue 12): the whole closed loop runs in :func:`run_chunk`, no Python per sample; a plant
step (about 0.5 us, four per sample) walks only the nonzero entries of A(alpha), M(alpha) and
A^T D A in the order of the dense sums; it allocates nothing and takes its arrays without
reference counting. The linear solve eliminates the wheels and steering sides first (K is an
arrow, :func:`_arrow_solve`): no fill-in, ~20 % off the closed loop against the dense 9 x 9
Cholesky (which took ~40 % of a step); the velocities differ from it by round-off.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# Indices of the constant vector handed to the compiled code.
(_L, _B, _A, _R, _IG, _MB, _CB, _MU_MASS, _EU, _JUL, _JUR, _BW, _DVL, _DCL, _DVR, _DCR, _DVW, _DCW,
 _CLONG, _CLAT, _MU, _FZ, _V0, _COUL, _VSTICK, _RATIO, _VSTRIB, _EPS, _TLIM, _KSTOP, _DSTOP, _RW, _NCONST) = range(33)
_NCONST += 3  # _RW .. _RW + 3: true rolling radius of each wheel

#: Compiled and cached; a division by zero gives inf or nan (caught as divergence) instead of a
#: Python exception, which spares a check at every division.
_jit = njit(cache=True, error_model="numpy")
#: The same for kernels that allocate nothing: without numba's runtime (private flag ``_nrt``)
#: they take their arrays without reference counting (~30 atomic operations per plant step, ~9 %).
_jit_borrow = njit(cache=True, error_model="numpy", _nrt=False)


# --- plant (see plant.py) ---
#
# The hot path: one step costs three sine/cosine pairs (the steering angles and the heading) and
# walks only the nonzero entries of A(alpha) and M(alpha), in the order of the dense sums, so the
# results equal those of the dense products bit for bit.

@_jit_borrow
def _unit_frame(c, i):
    """Side index, side sign, heading sign and steering axis position of wheel i."""
    side = 0 if i < 2 else 1
    s = 1.0 if i < 2 else -1.0
    h = 1.0 if i % 2 == 0 else -1.0
    return side, s, h, c[_L] / 2 * h, c[_B] / 2 * s


@_jit_borrow
def _unit_trig(alpha_l, alpha_r, tr):
    """cos and sin (4, 2) of each wheel's heading h_i alpha_side (cos and sin are even and odd)."""
    for j in range(2):
        a = alpha_l if j == 0 else alpha_r
        ca, sa = math.cos(a), math.sin(a)
        tr[2 * j, 0], tr[2 * j, 1] = ca, sa
        tr[2 * j + 1, 0], tr[2 * j + 1, 1] = ca, -sa


@_jit_borrow
def _inertia_terms(c, tr, v, M, bias):
    """Mass matrix M(alpha) (9, 9) and Coriolis and centrifugal forces h(alpha, v) (9,) of the
    plant (body-frame velocities) from the unit headings ``tr``."""
    M[:, :] = 0.0
    M[0, 0] = c[_MB]
    M[1, 1] = c[_MB]
    M[2, 2] = c[_CB]
    bias[:] = 0.0
    w = v[2]
    bias[0] = -c[_MB] * w * v[1]
    bias[1] = c[_MB] * w * v[0]
    m_u, e = c[_MU_MASS], c[_EU]
    for i in range(4):
        side, s, h, cx, cy = _unit_frame(c, i)
        ct, st = tr[i, 0], tr[i, 1]
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
        if m_u == 0.0:
            continue
        ad = v[3 + side]
        # velocity of the unit's centre of mass (body components)
        wx = v[0] - w * py + dpx * ad
        wy = v[1] + w * px + dpy * ad
        # J_dot v = omega z x p_dot + d2p/dalpha2 alpha_dot^2 ; d2p/dalpha2 = -s e (-sin, cos)
        pdx, pdy = dpx * ad, dpy * ad
        ax = -w * pdy + (s * e * st) * ad * ad - w * wy
        ay = w * pdx + (-s * e * ct) * ad * ad + w * wx
        bias[0] += m_u * ax
        bias[1] += m_u * ay
        bias[2] += m_u * (-py * ax + px * ay)
        bias[3 + side] += m_u * (dpx * ax + dpy * ay)
    for i in range(4):
        M[5 + i, 5 + i] = c[_BW]


@_jit
def _mass_matrix(c, alpha, M):
    """Mass matrix M(alpha) (9, 9) of the plant (body-frame velocities)."""
    tr = np.empty((4, 2))
    _unit_trig(alpha[0], alpha[1], tr)
    _inertia_terms(c, tr, np.zeros(9), M, np.empty(9))


@_jit
def _bias(c, alpha, v, out):
    """Coriolis and centrifugal forces h(alpha, v) (9,) of the plant in body-frame velocities."""
    tr = np.empty((4, 2))
    _unit_trig(alpha[0], alpha[1], tr)
    _inertia_terms(c, tr, v, np.empty((9, 9)), out)


@_jit_borrow
def _constraint_rows(c, tr, A):
    """The nonzero entries of A(alpha) (8, 9) of eq. (1)-(2) with the true rolling radii, as
    ``kinematics.constraint_matrix_into`` computes them; the structural zeros of A are left alone.
    Row i: lateral slip (columns 0-2); row 4 + i: longitudinal (0-2, 3 + side, 5 + i)."""
    for i in range(4):
        side, s_i, h, cx, cy = _unit_frame(c, i)
        co, s = tr[i, 0], tr[i, 1]
        A[i, 0], A[i, 1], A[i, 2] = -s, co, s * cy + co * cx
        A[4 + i, 0], A[4 + i, 1], A[4 + i, 2] = co, s, -co * cy + s * cx - s_i * c[_A]
        A[4 + i, 3 + side] = -s_i * c[_A] * h
        A[4 + i, 5 + i] = -c[_RW + i]


@_jit_borrow
def _slip_velocities(A, v, out):
    """out = A v (8,) over the nonzero entries of A (summed in the order of the dense product)."""
    for i in range(4):
        a = 3 if i < 2 else 4
        out[i] = 0.0 + A[i, 0] * v[0] + A[i, 1] * v[1] + A[i, 2] * v[2]
        out[4 + i] = (0.0 + A[4 + i, 0] * v[0] + A[4 + i, 1] * v[1] + A[4 + i, 2] * v[2]
                      + A[4 + i, a] * v[a] + A[4 + i, 5 + i] * v[5 + i])


@_jit_borrow
def _tanh_ratio(x2):
    """tanh(x) / x from x^2: below x = 0.2 (the tyres' usual range) by its Taylor series, the
    coefficients 2^2n (2^2n - 1) B_2n / (2n)! (terms beyond the last < 1e-19), which spares tanh,
    a square root and a division; above by tanh."""
    if x2 < 0.04:
        return 1.0 + x2 * (-0.3333333333333333 + x2 * (0.13333333333333333 + x2 * (-0.05396825396825397 + x2 * (
            0.021869488536155203 + x2 * (-0.008863235529902197 + x2 * (0.003592128036572481 + x2 * (
                -0.0014558343870513183 + x2 * (0.000590027440945586 + x2 * (-0.00023912911424355248 + x2 * (
                    9.691537956929451e-05 + x2 * -3.927832388331683e-05))))))))))
    x = math.sqrt(x2)
    return math.tanh(x) / x


@_jit_borrow
def _iteration_matrix(M, A, d, dt, K):
    """Lower triangle of K = M + dt A^T diag(d) A (9, 9) over the nonzero entries of A: the chassis
    columns 0-2 meet every row of A, steering side j the longitudinal rows 4 + 2j, 5 + 2j, wheel i row 4 + i."""
    for p in range(3):
        for q in range(p + 1):
            t = 0.0
            for j in range(8):
                t += A[j, p] * d[j] * A[j, q]
            K[p, q] = M[p, q] + dt * t
    for p in range(3, 5):
        j0 = 4 if p == 3 else 6
        for q in range(3):
            K[p, q] = M[p, q] + dt * (0.0 + A[j0, p] * d[j0] * A[j0, q] + A[j0 + 1, p] * d[j0 + 1] * A[j0 + 1, q])
        K[p, p] = M[p, p] + dt * (0.0 + A[j0, p] * d[j0] * A[j0, p] + A[j0 + 1, p] * d[j0 + 1] * A[j0 + 1, p])
    K[4, 3] = M[4, 3]
    for i in range(4):
        p, j, a = 5 + i, 4 + i, 3 if i < 2 else 4
        for q in range(3):
            K[p, q] = M[p, q] + dt * (0.0 + A[j, p] * d[j] * A[j, q])
        K[p, a] = M[p, a] + dt * (0.0 + A[j, p] * d[j] * A[j, a])
        K[p, 7 - a] = M[p, 7 - a]
        for q in range(5, p):
            K[p, q] = M[p, q]
        K[p, p] = M[p, p] + dt * (0.0 + A[j, p] * d[j] * A[j, p])


@_jit_borrow
def _coulomb(c, v, d_c):
    """Coulomb friction force magnitude-signed F(v), its secant F/v and its slope dF/dv (>= 0)."""
    mode = c[_COUL]
    av = abs(v)
    if mode == 2.0:
        return 0.0, 0.0, 0.0
    if mode == 1.0:
        eps = c[_EPS]
        x = v / eps
        f = d_c * math.tanh(x)
        sec = d_c / eps if abs(x) < 1e-8 else f / v
        return f, sec, d_c / eps / math.cosh(min(abs(x), 300.0)) ** 2
    vs = c[_VSTICK]
    if c[_RATIO] == 1.0:  # no breakaway peak: the level is d_c (skips the exponential)
        return (d_c * v / vs, d_c / vs, d_c / vs) if av <= vs else (d_c * (1.0 if v > 0 else -1.0), d_c / av, 0.0)
    e = math.exp(-(av / c[_VSTRIB]) ** 2)
    level = d_c * (1.0 + (c[_RATIO] - 1.0) * e)
    if av <= vs:
        return level * v / vs, level / vs, level / vs
    dlevel = d_c * (c[_RATIO] - 1.0) * e * (-2.0 * av / c[_VSTRIB] ** 2)
    return level * (1.0 if v > 0 else -1.0), level / av, max(dlevel, 0.0)


@_jit_borrow
def _friction_terms(c, v, d_v, d_c, inertia, dt):
    """Linearly-implicit friction of one joint: force = d * v_new + e.

    Fast joints use the tangent (Rosenbrock-Euler) linearisation, exact for a constant Coulomb
    force; slow joints, which one step of friction could stop (|v| < 2 dt d_c / inertia), use the
    secant, which never flips the sign of v and holds a stuck joint.
    """
    f, sec, slope = _coulomb(c, v, d_c)
    v_thr = max(2.0 * dt * d_c / inertia, 3.0 * c[_VSTICK])
    if abs(v) < v_thr:
        return d_v + sec, 0.0
    return d_v + slope, f - slope * v


@njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def _into_chassis(K, rhs, k0, k1, k2, f0, f1, f2, y):  # pragma: no cover - compiled
    """Eliminate one joint coupled to the chassis by ``(k0, k1, k2)`` (``f = k / pivot``, ``y`` its
    right-hand side) from the chassis block of K's lower triangle and from rhs."""
    K[0, 0] -= f0 * k0
    K[1, 0] -= f1 * k0
    K[1, 1] -= f1 * k1
    K[2, 0] -= f2 * k0
    K[2, 1] -= f2 * k1
    K[2, 2] -= f2 * k2
    rhs[0] -= f0 * y
    rhs[1] -= f1 * y
    rhs[2] -= f2 * y


@_jit_borrow
def _arrow_solve(K, rhs):
    """Solve K x = rhs in place for the plant's K (lower triangle read and overwritten); x in rhs.

    K is an arrow: each wheel (5-8) couples only to the chassis (0-2) and its steering side (3, 4),
    each steering side only to the chassis. Eliminating the wheels, then the steering sides, then
    the chassis block (LDL^T) makes no fill-in: about a third of the operations of a dense 9 x 9
    Cholesky and a much shorter chain of dependent ones (K is symmetric positive definite: no pivoting).
    """
    for i in range(4):
        p, a = 5 + i, 3 if i < 2 else 4
        k0, k1, k2, ka = K[p, 0], K[p, 1], K[p, 2], K[p, a]
        inv = 1.0 / K[p, p]
        f0, f1, f2, fa = k0 * inv, k1 * inv, k2 * inv, ka * inv
        y = rhs[p]
        _into_chassis(K, rhs, k0, k1, k2, f0, f1, f2, y)
        K[a, 0] -= fa * k0
        K[a, 1] -= fa * k1
        K[a, 2] -= fa * k2
        K[a, a] -= fa * ka
        rhs[a] -= fa * y
    for a in range(3, 5):
        k0, k1, k2 = K[a, 0], K[a, 1], K[a, 2]
        inv = 1.0 / K[a, a]
        _into_chassis(K, rhs, k0, k1, k2, k0 * inv, k1 * inv, k2 * inv, rhs[a])
    # chassis block: LDL^T, forward and back substitution
    d0 = K[0, 0]
    l10, l20 = K[1, 0] / d0, K[2, 0] / d0
    d1 = K[1, 1] - l10 * K[1, 0]
    k21 = K[2, 1] - l20 * K[1, 0]
    l21 = k21 / d1
    d2 = K[2, 2] - l20 * K[2, 0] - l21 * k21
    y1 = rhs[1] - l10 * rhs[0]
    y2 = rhs[2] - l20 * rhs[0] - l21 * y1
    x2 = y2 / d2
    x1 = y1 / d1 - l21 * x2
    x0 = rhs[0] / d0 - l10 * x1 - l20 * x2
    rhs[0], rhs[1], rhs[2] = x0, x1, x2
    for a in range(3, 5):
        rhs[a] = (rhs[a] - K[a, 0] * x0 - K[a, 1] * x1 - K[a, 2] * x2) / K[a, a]
    for i in range(4):
        p, a = 5 + i, 3 if i < 2 else 4
        rhs[p] = (rhs[p] - K[p, 0] * x0 - K[p, 1] * x1 - K[p, 2] * x2 - K[p, a] * rhs[a]) / K[p, p]


@_jit
def workspace():
    """Scratch arrays of :func:`plant_step`: M, K (9, 9), A (8, 9) (zeros kept), h, rhs (9,),
    slip, dvec (8,), joint friction (2, 9), unit headings (4, 2)."""
    return (np.zeros((9, 9)), np.zeros((9, 9)), np.zeros((8, 9)), np.zeros(9), np.zeros(9), np.zeros(8),
            np.zeros(8), np.zeros((2, 9)), np.zeros((4, 2)))


@_jit_borrow
def plant_step(c, pos, vel, torque, dt, work, mu_w, M, K, A, h, rhs, slip, dvec, jf, tr):
    """Advance the plant by one linearly-implicit Euler step of length dt (in place); returns the
    kinetic energy 0.5 v^T M(alpha) v before the step.

    ``torque``: motor torques (4,) after the drive's limit; ``work`` (3,) accumulates
    (motor work, dissipated work, stop work) over the step, evaluated at the new velocities;
    ``mu_w`` (4,): factor on the friction coefficient of each wheel (1: the floor's mu);
    ``M`` .. ``tr``: scratch arrays from :func:`workspace` (explicit: no reference counting per step).
    """
    a_l, a_r = pos[3], pos[4]
    _unit_trig(a_l, a_r, tr)
    _inertia_terms(c, tr, vel, M, h)
    _constraint_rows(c, tr, A)
    energy = 0.0
    for p in range(5):
        for q in range(5):
            energy += vel[p] * M[p, q] * vel[q]
    for p in range(5, 9):
        energy += vel[p] * M[p, p] * vel[p]
    # slip velocities and tyre secant coefficients (lagged)
    _slip_velocities(A, vel, slip)
    for i in range(4):
        mufz = c[_MU] * mu_w[i] * c[_FZ]
        v_contact = slip[4 + i] + c[_RW + i] * vel[5 + i]
        V = max(abs(c[_RW + i] * vel[5 + i]), math.sqrt(v_contact**2 + slip[i] ** 2), c[_V0])
        d_lat, d_long = c[_CLAT] / V, c[_CLONG] / V
        g = _tanh_ratio(((d_lat * slip[i]) ** 2 + (d_long * slip[4 + i]) ** 2) / (mufz * mufz))
        dvec[i] = d_lat * g
        dvec[4 + i] = d_long * g
    # K = M + dt (A^T D A + joint damping), joint friction force d v_new + e
    _iteration_matrix(M, A, dvec, dt, K)
    jf[0, 3], jf[1, 3] = _friction_terms(c, vel[3], c[_DVL], c[_DCL], M[3, 3], dt)
    jf[0, 4], jf[1, 4] = _friction_terms(c, vel[4], c[_DVR], c[_DCR], M[4, 4], dt)
    for i in range(4):
        jf[0, 5 + i], jf[1, 5 + i] = _friction_terms(c, vel[5 + i], c[_DVW], c[_DCW], M[5 + i, 5 + i], dt)
    for q in range(3, 9):
        K[q, q] += dt * jf[0, q]
    # right-hand side M v - dt h + dt B u (+ stops); M is zero outside 0-4 but on the diagonal
    for p in range(5):
        t = 0.0
        for q in range(5):
            t += M[p, q] * vel[q]
        rhs[p] = t - dt * h[p]
    for p in range(5, 9):
        rhs[p] = (0.0 + M[p, p] * vel[p]) - dt * h[p]
    for i in range(4):
        rhs[5 + i] += dt * c[_IG] * torque[i]
    for q in range(3, 9):
        rhs[q] -= dt * jf[1, q]
    lim = 0.5 * math.pi
    pen0 = a_l - lim if a_l > lim else (a_l + lim if a_l < -lim else 0.0)
    pen1 = a_r - lim if a_r > lim else (a_r + lim if a_r < -lim else 0.0)
    for j, pen in ((0, pen0), (1, pen1)):
        if pen != 0.0:
            K[3 + j, 3 + j] += dt * (c[_DSTOP] + dt * c[_KSTOP])
            rhs[3 + j] -= dt * c[_KSTOP] * pen
    _arrow_solve(K, rhs)
    # energy accounts at the new velocities
    p_motor = 0.0
    for i in range(4):
        p_motor += c[_IG] * torque[i] * rhs[5 + i]
    p_diss = 0.0
    _slip_velocities(A, rhs, slip)
    for j in range(8):
        p_diss += dvec[j] * slip[j] * slip[j]
    for q in range(3, 9):
        p_diss += (jf[0, q] * rhs[q] + jf[1, q]) * rhs[q]
    p_stop = 0.0
    for j, pen in ((0, pen0), (1, pen1)):
        if pen != 0.0:
            p_stop -= (c[_KSTOP] * (pen + dt * rhs[3 + j]) + c[_DSTOP] * rhs[3 + j]) * rhs[3 + j]
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
    return 0.5 * energy


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
    for k in range(k0, k1):
        read_sensors(pos, k, wheel_res, steer_res, steer_noise, alpha_m, beta_m)
        controller_step(g, Ts, k, alpha_m, beta_m, u_ff, mode_d, alpha_d, alpha_dot_d, beta_d, beta_dot_d, cstate, u)
        for i in range(4):
            ua[i] = min(max(u[i], -lim), lim)
            if burst[k, i] != 0.0:
                ua[i] += burst[k, i]
        out_pos[k] = pos
        out_vel[k] = vel
        out_alpha[k] = alpha_m
        out_beta[k] = beta_m
        out_work[k] = work
        for i in range(4):
            out_cmd[k, i] = u[i]
            out_app[k, i] = ua[i]
            out_meas[k, i] = ua[i] + torque_offset[i] + torque_noise[k, i]
        for j in range(substeps):
            if n_patches > 0:
                patch_factors(c, pos, t[k] + j * dt, patches, mu_w)
            e = plant_step(c, pos, vel, ua, dt, work, mu_w, M, K, A, h, rhs, slip, dvec, jf, tr)
            if j == 0:  # the energy at the sample, from the step's M(alpha)
                out_energy[k] = e
