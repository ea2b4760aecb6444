"""Compiled plant of the simulation (numba): the constants vector's layout, the plant's mass
matrix, constraints, friction and tyres, the linear solve and one plant step (:func:`plant_step`).
The closed loop that drives it (sensors, controller, :func:`agvdyn.simulation._kernels.run_chunk`)
is in :mod:`._kernels`; the physics and the design choices are documented in plant.py.

Speed (issue 12): a plant step (about 0.5 us, four per sample) walks only the nonzero entries of
A(alpha), M(alpha) and A^T D A in the order of the dense sums; it allocates nothing and takes its
arrays without reference counting. The linear solve eliminates the wheels and steering sides first
(K is an arrow, :func:`_arrow_solve`): no fill-in, ~20 % off the closed loop against the dense
9 x 9 Cholesky (which took ~40 % of a step); the velocities differ from it by round-off.
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn._jit import njit
from agvdyn.simulation._arrow_solve import _arrow_solve

# Indices of the constant vector handed to the compiled code.
(_L, _B, _A, _R, _IG, _MB, _CB, _MU_MASS, _EU, _JUL, _JUR, _BW, _DVL, _DCL, _DVR, _DCR, _DVW, _DCW,
 _CLONG, _CLAT, _MU, _FZ, _V0, _COUL, _VSTICK, _EPS, _TLIM, _KSTOP, _DSTOP, _RW, _NCONST) = range(31)
_NCONST += 3  # _RW .. _RW + 3: true rolling radius of each wheel
#: Breakaway friction per joint group (model_spec.FRICTION_GROUPS order: left steering, right
#: steering, wheels): ``_RATIO + g`` the ratio d_s / d_c, ``_VSTRIB + g`` the Stribeck velocity w_s.
_RATIO, _VSTRIB = _NCONST, _NCONST + 3
_NCONST += 6
_GROUP_L, _GROUP_R, _GROUP_W = 0, 1, 2
#: Payload carried by the chassis (simulation/payload.py): mass m_p, first moments m_p x_p and m_p y_p
#: about the reference point, yaw inertia J_p about the reference point (zero without a payload).
_PM, _PSX, _PSY, _PJ = range(_NCONST, _NCONST + 4)
_NCONST += 4

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
def _payload_terms(c, v, M, bias):
    """Add the payload, a rigid body fixed to the chassis, to M and h (plant.py, "Payload"):
    mass m_p, first moments (S_x, S_y) = m_p (x_p, y_p), yaw inertia J_p about the reference point.
    Velocity of its centre (v_x - omega y_p, v_y + omega x_p); the kinetic energy
    ``m_p/2 (v_x^2 + v_y^2) + J_p/2 omega^2 + omega (S_x v_y - S_y v_x)`` gives
    ``M[0,0] = M[1,1] = m_p``, ``M[2,2] = J_p``, ``M[0,2] = -S_y``, ``M[1,2] = S_x`` and the forces of
    the body-frame (quasi-velocity) equations ``h = (-omega (m_p v_y + omega S_x),
    omega (m_p v_x - omega S_y), omega (S_x v_x + S_y v_y))``, which do no work (v . h = 0)."""
    m, sx, sy = c[_PM], c[_PSX], c[_PSY]
    w = v[2]
    M[0, 0] += m
    M[1, 1] += m
    M[2, 2] += c[_PJ]
    M[0, 2] -= sy
    M[2, 0] -= sy
    M[1, 2] += sx
    M[2, 1] += sx
    bias[0] -= w * (m * v[1] + w * sx)
    bias[1] += w * (m * v[0] - w * sy)
    bias[2] += w * (sx * v[0] + sy * v[1])


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
    if c[_PM] != 0.0 or c[_PJ] != 0.0:
        _payload_terms(c, v, M, bias)
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
def _coulomb(c, v, d_c, group):
    """Coulomb friction force magnitude-signed F(v), its secant F/v and its slope dF/dv (>= 0) of a
    joint of ``group`` (0: left steering, 1: right steering, 2: wheels; its breakaway ratio and
    Stribeck velocity at ``_RATIO + group``, ``_VSTRIB + group``)."""
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
    ratio = c[_RATIO + group]
    if ratio == 1.0:  # no breakaway peak: the level is d_c (skips the exponential)
        return (d_c * v / vs, d_c / vs, d_c / vs) if av <= vs else (d_c * (1.0 if v > 0 else -1.0), d_c / av, 0.0)
    w_s = c[_VSTRIB + group]
    e = math.exp(-(av / w_s) ** 2)
    level = d_c * (1.0 + (ratio - 1.0) * e)
    if av <= vs:
        return level * v / vs, level / vs, level / vs
    dlevel = d_c * (ratio - 1.0) * e * (-2.0 * av / w_s ** 2)
    return level * (1.0 if v > 0 else -1.0), level / av, max(dlevel, 0.0)


@_jit_borrow
def _slow_speed(c, d_c, inertia, dt):
    """Speed below which one step of Coulomb friction could stop a joint (>= 3 stick velocities)."""
    return max(2.0 * dt * d_c / inertia, 3.0 * c[_VSTICK])


@_jit_borrow
def secant_damping(c, v, d_v, d_c, group):
    """``d`` of the secant friction force ``d v_new`` of a slow joint: ``d_v + F(v) / v``."""
    return d_v + _coulomb(c, v, d_c, group)[1]


@_jit_borrow
def _friction_terms(c, v, d_v, d_c, group, inertia, dt):
    """Linearly-implicit friction of one joint of joint group ``group`` (:func:`_coulomb`):
    force = d * v_new + e; the third value is 1 where a slow joint took the tangent.

    Fast joints use the tangent (Rosenbrock-Euler) linearisation, exact for a constant Coulomb
    force; slow joints, which one step of friction could stop (:func:`_slow_speed`), the secant,
    which never flips the sign of v and holds a stuck joint. With stiction, a slow joint outside the
    stick band takes the tangent too (the caller falls back to the secant where it reverses the
    joint): the secant ``level v_new / |v_old|`` exceeds the level while a joint breaks away (v grows)
    and held joints until their torque was 3-21 % above the level.
    """
    av = abs(v)
    slow = av < _slow_speed(c, d_c, inertia, dt)
    if slow and not (c[_COUL] == 0.0 and av > c[_VSTICK]):
        return secant_damping(c, v, d_v, d_c, group), 0.0, 0
    f, _, slope = _coulomb(c, v, d_c, group)
    return d_v + slope, f - slope * v, 1 if slow else 0


@_jit_borrow
def _joint_constants(c, q):
    """Group, viscous and Coulomb coefficient of joint q (3, 4: steering; 5-8: wheels)."""
    if q < 5:
        return (_GROUP_L, c[_DVL], c[_DCL]) if q == 3 else (_GROUP_R, c[_DVR], c[_DCR])
    return _GROUP_W, c[_DVW], c[_DCW]


@_jit_borrow
def _secant_where_reversed(c, vel, v_new, jf, slow):
    """The slow joints on the tangent (``slow``: bit q for joint q, :func:`_friction_terms`) whose
    velocity the step reversed take the secant in ``jf``; True when there was one (solve again)."""
    redo = False
    for q in range(3, 9):
        if (slow >> q) & 1 and v_new[q] * vel[q] < 0.0:
            group, d_v, d_c = _joint_constants(c, q)
            jf[0, q], jf[1, q] = secant_damping(c, vel[q], d_v, d_c, group), 0.0
            redo = True
    return redo


@_jit_borrow
def _assemble(c, pos, vel, torque, dt, M, A, h, dvec, jf, K, rhs):
    """K = M + dt (A^T D A + joint damping + stops) and rhs = M v - dt h + dt B u - dt e (+ stops) of
    one step; returns the steering angles' penetration of their stops."""
    _iteration_matrix(M, A, dvec, dt, K)
    for q in range(3, 9):
        K[q, q] += dt * jf[0, q]
    # M is zero outside 0-4 but on the diagonal
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
    a_l, a_r = pos[3], pos[4]
    pen0 = a_l - lim if a_l > lim else (a_l + lim if a_l < -lim else 0.0)
    pen1 = a_r - lim if a_r > lim else (a_r + lim if a_r < -lim else 0.0)
    for j, pen in ((0, pen0), (1, pen1)):
        if pen != 0.0:
            K[3 + j, 3 + j] += dt * (c[_DSTOP] + dt * c[_KSTOP])
            rhs[3 + j] -= dt * c[_KSTOP] * pen
    return pen0, pen1


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
    _unit_trig(pos[3], pos[4], tr)
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
    # joint friction force d v_new + e; K = M + dt (A^T D A + joint damping), the right-hand side
    jf[0, 3], jf[1, 3], slow = _friction_terms(c, vel[3], c[_DVL], c[_DCL], _GROUP_L, M[3, 3], dt)
    jf[0, 4], jf[1, 4], s = _friction_terms(c, vel[4], c[_DVR], c[_DCR], _GROUP_R, M[4, 4], dt)
    slow = (slow << 3) | (s << 4)
    for i in range(4):
        jf[0, 5 + i], jf[1, 5 + i], s = _friction_terms(c, vel[5 + i], c[_DVW], c[_DCW], _GROUP_W, M[5 + i, 5 + i], dt)
        slow |= s << (5 + i)
    pen0, pen1 = _assemble(c, pos, vel, torque, dt, M, A, h, dvec, jf, K, rhs)
    _arrow_solve(K, rhs)
    if slow and _secant_where_reversed(c, vel, rhs, jf, slow):
        pen0, pen1 = _assemble(c, pos, vel, torque, dt, M, A, h, dvec, jf, K, rhs)
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
