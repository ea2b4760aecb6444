"""Compiled kernels of the row pipeline: each fuses what the numpy formulation did in many passes
over small temporaries, one sample at a time, and releases the GIL (recordings in threads).

* :func:`stretch_motion`: derivatives of the filtered angles (``np.gradient``, second order, also
  at the ends), odometry of eq. (3) and the slip speed of each contact point (one wheel left out,
  :func:`agvdyn.odometry.wheel_slip_row`; from the steering rates of the lighter slip filter and
  the raw wheel rates, so that a slip of a few tens of ms is neither smeared nor shrunk), chassis
  accelerations, the 21 entries of Theta (eq. 16) and the torques aligned to the angle instants,
  written into the padded buffer of the second zero-phase filter;
* :func:`stretch_modes`: the motion mode of every row (eq. 9 and the rules of
  :func:`agvdyn.identification.rows.row_modes`);
* :func:`stretch_projection`: the rows of eq. (19), ``H_k^T Theta``, ``H_k^T B u``, the
  generalized velocities and the kept rows (stiction mask and guard) of every run of one mode;
* :func:`kept_rows`: the kept rows of a log's blocks, ``[H_k^T Theta | H_k^T B | H_k^T B u]``, in
  one array (the input of the normal equations and of the row store).

Each reproduces the numpy formulation operation by operation (same results to the last bit but
for the order of a few sums); ``tests/test_kernels.py`` compares them.
"""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit
from agvdyn._numba_cache import drop_stale_cache
from agvdyn import _trig
from agvdyn._trig import sincos_steering
from agvdyn import odometry
from agvdyn.kinematics import car_like_model_into, constraints, icr_state_trig, models, wheel_frame
from agvdyn.odometry import wheel_slip_row

drop_stale_cache(__file__, constraints.__file__, models.__file__, _trig.__file__, odometry.__file__)

__all__ = ["stretch_motion", "stretch_modes", "stretch_projection", "kept_rows", "recording_breaks", "copy_rows",
           "SIGNAL_CHANNELS"]

#: Channels of the second filter: the 21 entries of Theta and the 4 motor torques.
SIGNAL_CHANNELS = 25
@njit(cache=True, nogil=True, inline="always")
def _derivative(x, i, c, dt, half_rate):  # pragma: no cover - compiled
    """Row i of column c of ``np.gradient(x, dt, axis=0, edge_order=2)`` (``half_rate = 0.5 / dt``:
    a product instead of numpy's division inside, equal to the last bit or one unit of it)."""
    n = x.shape[0]
    if i == 0:
        return -1.5 / dt * x[0, c] + 2.0 / dt * x[1, c] + -0.5 / dt * x[2, c]
    if i == n - 1:
        return 0.5 / dt * x[n - 3, c] + -2.0 / dt * x[n - 2, c] + 1.5 / dt * x[n - 1, c]
    return (x[i + 1, c] - x[i - 1, c]) * half_rate


@njit(cache=True, nogil=True, inline="always")
def _odometry_row(j, al, ar, l, b, a, r, qd, trig, A, rhs, rates, slip_rhs, P):  # pragma: no cover - compiled
    """Chassis velocities of eq. (3) of row j, as ``agvdyn.odometry._odometry`` (the rows of eq. 1-2
    without their zeros; same sums); ``slip_rhs`` the right-hand side of the same rows with the
    slip's rates ``rates`` (alpha_l_dot, alpha_r_dot, beta_dot x 4), ``P`` = ``(A_ch^T A_ch)^-1``."""
    sl, cl = sincos_steering(al)
    sr, cr = sincos_steering(ar)
    trig[j, 0], trig[j, 1], trig[j, 2], trig[j, 3] = sl, cl, sr, cr
    ad0, ad1 = qd[j, 3], qd[j, 4]
    for i in range(4):
        left, sigma, side, cx, cy = wheel_frame(i, l, b)
        c = cl if left else cr
        s = sigma * (sl if left else sr)
        A[i, 0], A[i, 1], A[i, 2] = -s, c, s * cy + c * cx
        A[4 + i, 0], A[4 + i, 1], A[4 + i, 2] = c, s, -c * cy + s * cx - side * a
        steer = -side * a * sigma
        rhs[i] = 0.0
        rhs[4 + i] = -(steer * (ad0 if left else ad1)) - (-r) * qd[j, 5 + i]
        slip_rhs[i] = 0.0
        slip_rhs[4 + i] = -(steer * (rates[0] if left else rates[1])) - (-r) * rates[2 + i]
    m00 = m01 = m02 = m11 = m12 = m22 = 0.0
    g0 = g1 = g2 = 0.0
    for row in range(8):
        a0, a1, a2 = A[row, 0], A[row, 1], A[row, 2]
        if row >= 4:
            g0 += a0 * rhs[row]
            g1 += a1 * rhs[row]
            g2 += a2 * rhs[row]
        m00 += a0 * a0
        m01 += a0 * a1
        m02 += a0 * a2
        m11 += a1 * a1
        m12 += a1 * a2
        m22 += a2 * a2
    c00 = m11 * m22 - m12 * m12
    c01 = m12 * m02 - m01 * m22
    c02 = m01 * m12 - m11 * m02
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    det = m00 * c00 + m01 * c01 + m02 * c02
    v0 = (c00 * g0 + c01 * g1 + c02 * g2) / det
    v1 = (c01 * g0 + c11 * g1 + c12 * g2) / det
    v2 = (c02 * g0 + c12 * g1 + c22 * g2) / det
    qd[j, 0], qd[j, 1], qd[j, 2] = v0, v1, v2
    inv = 1.0 / det
    P[0, 0], P[0, 1], P[0, 2] = c00 * inv, c01 * inv, c02 * inv
    P[1, 0], P[1, 1], P[1, 2] = c01 * inv, c11 * inv, c12 * inv
    P[2, 0], P[2, 1], P[2, 2] = c02 * inv, c12 * inv, c22 * inv


def stretch_motion(f, fast, wheels, dt, l, b, a, r, eps, torque, lead, alpha, trig, qd, slip, sig,
                   scratch=None) -> None:
    """See :func:`_stretch_motion`; the six friction entries ``tanh(q_dot / eps)`` are taken after
    the sweep by numpy's vectorised tanh on one contiguous array (``scratch`` (n, 6), optional): a
    scalar libm tanh per entry had been a third of the sweep."""
    arg = np.empty((f.shape[0], 6)) if scratch is None else scratch
    _stretch_motion(f, fast, wheels, dt, l, b, a, r, eps, torque, lead, alpha, trig, qd, slip, sig, arg)
    np.tanh(arg, out=arg)
    _scatter_friction(arg, sig)


@njit(cache=True, nogil=True)
def _scatter_friction(arg, sig):  # pragma: no cover - compiled
    """The friction entries ``tanh(q_dot / eps)`` (n, 6) into their columns 5, 8, 17-20 of ``sig``."""
    for j in range(arg.shape[0]):
        sig[j, 5], sig[j, 8] = arg[j, 0], arg[j, 1]
        for w in range(4):
            sig[j, 17 + w] = arg[j, 2 + w]


@njit(cache=True, nogil=True)
def copy_rows(dst, src):  # pragma: no cover - compiled
    """``dst[:] = src`` for 2-D arrays of any strides (numpy's strided copy of a few columns is 2x slower)."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@njit(cache=True, nogil=True)
def _stretch_motion(f, fast, wheels, dt, l, b, a, r, eps, torque, lead, alpha, trig, qd, slip, sig,
                    arg):  # pragma: no cover - compiled
    """One filtered stretch: ``f`` (n, 6) filtered (alpha_l, alpha_r, beta_fl..rr), ``fast`` (n, 2)
    the steering angles through the slip filter, ``wheels`` (n, 4) the raw wheel angles. Writes
    ``alpha`` (n, 2) clipped to the stops, ``trig`` (n, 4) their (sin, cos) left and right,
    ``qd`` (n, 9) joint velocities (chassis by odometry, eq. 3; their derivatives, the
    accelerations, enter the signals and are not kept),
    ``slip`` (n, 4) slip speed per contact point (m/s; rates of ``fast`` and ``wheels``, angles of
    ``f``), ``sig`` (n, 25) the entries of Theta
    (:data:`agvdyn.dynamics.REGRESSOR_SIGNALS`) and the torques ``(1 - lead) m[k] + lead m[k-1]``.

    One sweep over the rows: row k's velocities and odometry, row k - 2's accelerations (their
    central differences need the velocities of k - 3 and k - 1) and its signals, so that every
    row is touched while in cache; derivatives as ``np.gradient(x, dt, edge_order=2)``."""
    n = f.shape[0]
    half_pi = np.pi / 2
    half_rate = 0.5 / dt
    per_eps = 1.0 / eps
    A = np.empty((8, 3))
    rhs = np.empty(8)
    slip_rhs = np.empty(8)
    e = np.empty(8)
    P = np.empty((3, 3))
    rates = np.empty(6)
    qdd = np.empty(9)
    for k in range(n + 2):
        if k < n:
            j = k
            for c in range(6):
                qd[j, 3 + c] = _derivative(f, j, c, dt, half_rate)
            al = min(max(f[j, 0], -half_pi), half_pi)
            ar = min(max(f[j, 1], -half_pi), half_pi)
            alpha[j, 0], alpha[j, 1] = al, ar
            for c in range(2):
                rates[c] = _derivative(fast, j, c, dt, half_rate)
            for c in range(4):
                rates[2 + c] = _derivative(wheels, j, c, dt, half_rate)
            _odometry_row(j, al, ar, l, b, a, r, qd, trig, A, rhs, rates, slip_rhs, P)
            wheel_slip_row(A, P, slip_rhs, e, slip, j)
        j = k - 2
        if j < 0:
            continue
        for c in range(9):
            qdd[c] = _derivative(qd, j, c, dt, half_rate)
        sig[j, 0] = qdd[0] - qd[j, 1] * qd[j, 2]
        sig[j, 1] = qdd[1] + qd[j, 0] * qd[j, 2]
        sig[j, 2] = qdd[2]
        for c in range(2):
            sig[j, 3 + 3 * c] = qdd[3 + c]
            sig[j, 4 + 3 * c] = qd[j, 3 + c]
            arg[j, c] = qd[j, 3 + c] * per_eps  # tanh taken by stretch_motion
        for w in range(4):
            sig[j, 9 + w] = qdd[5 + w]
            sig[j, 13 + w] = qd[j, 5 + w]
            arg[j, 2 + w] = qd[j, 5 + w] * per_eps
        for w in range(4):
            if lead == 0.0 or j == 0:
                sig[j, 21 + w] = torque[j, w]
            else:
                sig[j, 21 + w] = (1.0 - lead) * torque[j, w] + lead * torque[j - 1, w]


@njit(cache=True, nogil=True)
def stretch_modes(alpha, trig, qd, k_icr, limit, tol, nominal, h1, r, rest_speed, steering_rate, mode, av):
    # pragma: no cover - compiled
    """Mode of each row (1..5, 0 = in no mode of the model) as ``rows.row_modes``; ``nominal``
    (3, 2): steering of straight, rotation, lateral; ``h1`` (4, 2) wheel rows of H_1. ``av``: the
    virtual angle of the rows whose ICR state was needed (every row in mode 2)."""
    for j in range(alpha.shape[0]):
        al, ar = alpha[j, 0], alpha[j, 1]
        res = 0.0
        have_icr = False
        if abs(al - nominal[2, 0]) <= tol and abs(ar - nominal[2, 1]) <= tol:
            config = 3
        elif abs(al - nominal[1, 0]) <= tol and abs(ar - nominal[1, 1]) <= tol:
            config = 4
        elif abs(al - nominal[0, 0]) <= tol and abs(ar - nominal[0, 1]) <= tol:
            config = 5
        else:
            av[j], res = icr_state_trig(k_icr, trig[j, 0], trig[j, 1], trig[j, 2], trig[j, 3])
            have_icr = True
            config = 2 if abs(res) <= tol and abs(av[j]) <= limit + tol else 1
        ad0, ad1 = qd[j, 3], qd[j, 4]
        roll = 0.0
        for w in range(4):
            roll = max(roll, abs(qd[j, 5 + w] - (ad0 * h1[w, 0] + ad1 * h1[w, 1])))
        rest = roll * r < rest_speed
        steering = max(abs(ad0), abs(ad1)) > steering_rate
        m = config
        if rest:
            if steering:
                m = 1
        else:
            if config == 1:
                m = 0
            elif steering and config == 5:
                if not have_icr:
                    av[j], res = icr_state_trig(k_icr, trig[j, 0], trig[j, 1], trig[j, 2], trig[j, 3])
                m = 2 if abs(res) <= tol else 0
            elif steering and (config == 3 or config == 4):
                m = 0
        mode[j] = m


@njit(cache=True, nogil=True, inline="always")
def _project_row(H, dof, sig, torque, j, i_G, Y, tau):  # pragma: no cover - compiled
    """Row j of ``H_k^T Theta`` (dof, 11) from the entries of Theta ``sig[j]`` and ``H_k^T B u``
    (dof,) from the torques ``torque[j]``, as ``agvdyn.dynamics.project_signals``."""
    for c in range(dof):
        rot = H[2, c] * sig[j, 2]
        Y[j, c, 6] = H[0, c] * sig[j, 0] + H[1, c] * sig[j, 1]
        Y[j, c, 7] = rot
        Y[j, c, 0] = rot + H[3, c] * sig[j, 3]
        Y[j, c, 1] = H[3, c] * sig[j, 4]
        Y[j, c, 2] = H[3, c] * sig[j, 5]
        Y[j, c, 3] = rot + H[4, c] * sig[j, 6]
        Y[j, c, 4] = H[4, c] * sig[j, 7]
        Y[j, c, 5] = H[4, c] * sig[j, 8]
        bw = dv = dc = u = 0.0
        for w in range(4):
            h = H[5 + w, c]
            bw += h * sig[j, 9 + w]
            dv += h * sig[j, 13 + w]
            dc += h * sig[j, 17 + w]
            u += h * torque[j, w]
        Y[j, c, 10], Y[j, c, 8], Y[j, c, 9] = bw, dv, dc
        tau[j, c] = i_G * u


@njit(cache=True, nogil=True)
def stretch_projection(mode, av, qd, sig, torque, h_const, pinv_const, dofs, thresholds, usable, mine, guards,
                       l, b, a, r, limit, i_G, Y, tau, s_dot, keep, offsets, runs):  # pragma: no cover
    """Rows of eq. (19) of every run of one mode (mode != 0 with a usable row of its own) of a
    stretch: ``Y`` (n, 2, 11) ``H_k^T Theta``, ``tau`` (n, 2), ``s_dot`` (n, 2) ``H_k^+ q_dot``,
    ``offsets`` (n, 2, 4) ``H_k^T B e_i`` (mode 2 rows only; constant otherwise), ``keep`` (n, 2)
    ``|s_dot| >= threshold`` and usable, with ``guards[mode, slot]`` rows around a dropped row or
    the run's ends dropped too, and own rows only. Slots beyond the mode's dof are not written. ``runs``
    (n, 2) gets the runs; returns their number."""
    n = mode.shape[0]
    H = np.empty((9, 2))
    dH = np.empty((9, 2))
    P = np.empty((2, 9))
    n_runs = 0
    start = 0
    while start < n:
        m = mode[start]
        stop = start + 1
        while stop < n and mode[stop] == m:
            stop += 1
        used = False
        if m != 0:
            for j in range(start, stop):
                if usable[j] and mine[j]:
                    used = True
                    break
        if not used:
            start = stop
            continue
        runs[n_runs, 0], runs[n_runs, 1] = start, stop
        n_runs += 1
        dof = dofs[m]
        if m != 2:
            for i in range(9):
                for c in range(2):
                    H[i, c] = h_const[m, i, c]
                    P[c, i] = pinv_const[m, c, i]
        for j in range(start, stop):
            if m == 2:
                v = min(max(av[j], -limit), limit)
                car_like_model_into(l, b, a, r, v, H, dH)
                n00 = n01 = n11 = r0 = r1 = 0.0
                for i in range(9):
                    n00 += H[i, 0] * H[i, 0]
                    n01 += H[i, 0] * H[i, 1]
                    n11 += H[i, 1] * H[i, 1]
                    r0 += H[i, 0] * qd[j, i]
                    r1 += H[i, 1] * qd[j, i]
                det = n00 * n11 - n01 * n01
                s_dot[j, 0] = (r0 * n11 - n01 * r1) / det
                s_dot[j, 1] = (n00 * r1 - n01 * r0) / det
                for c in range(2):
                    for w in range(4):
                        offsets[j, c, w] = i_G * H[5 + w, c]
            else:
                for c in range(dof):
                    s = 0.0
                    for i in range(9):
                        s += P[c, i] * qd[j, i]
                    s_dot[j, c] = s
            _project_row(H, dof, sig, torque, j, i_G, Y, tau)
        for c in range(dof):
            thr = thresholds[m, c]
            guard = guards[m, c]
            last = start - 1  # the rows before the run count as dropped
            for j in range(start, stop):
                if not (abs(s_dot[j, c]) >= thr and usable[j]):
                    last = j
                keep[j, c] = j - last > guard
            nxt = stop  # and so do those after it
            for j in range(stop - 1, start - 1, -1):
                if not (abs(s_dot[j, c]) >= thr and usable[j]):
                    nxt = j
                keep[j, c] = keep[j, c] and nxt - j > guard and mine[j]
        start = stop
    return n_runs


@njit(cache=True, nogil=True)
def kept_rows(regressor, extra, torque, keep, sample, coord, slot_key, column, out, key, step,
              group, by_key, cursor, nonzero):  # pragma: no cover - compiled
    """Write the kept rows of one block's coordinate slots to ``out`` (m, 11 + q + 1): the
    columns of ``[regressor | extra]`` (``extra`` (n, dof, q): the columns after the paper's, motor-torque
    offsets and model extensions; q may be 0) at the positions ``column`` (natural column -> stored
    one), the torque last; ``key``, ``step``, ``group`` per row. Rows of slot c get key
    ``slot_key[c]`` and group ``coord[c]``; slot by slot, each in time order. Each row is also
    written to ``by_key[cursor[key]]`` (and the cursor advanced): the rows grouped by key, and
    ``nonzero[key, p]`` set where a row of the key has column p not zero. Returns the rows written."""
    n, dof = keep.shape
    w = out.shape[1]
    k = 0
    for c in range(dof):
        for j in range(n):
            if not keep[j, c]:
                continue
            for p in range(11):
                out[k, column[p]] = regressor[j, c, p]
            for p in range(extra.shape[2]):
                out[k, column[11 + p]] = extra[j, c, p]
            out[k, w - 1] = torque[j, c]
            key[k] = slot_key[c]
            step[k] = sample[j]
            group[k] = coord[c]
            dest = cursor[slot_key[c]]
            cursor[slot_key[c]] = dest + 1
            for p in range(w):
                v = out[k, p]
                by_key[dest, p] = v
                if v != 0.0:
                    nonzero[slot_key[c], p] = True
            k += 1
    return k


@njit(cache=True, nogil=True)
def recording_breaks(t, alpha, beta, max_step, max_steering_step, max_wheel_step, kind):  # pragma: no cover
    """Where a log's recording is not continuous: ``kind[i]`` (n - 1,) is 1 for a time step above
    ``max_step``, else 2 for a steering angle step above ``max_steering_step``, else 3 for a wheel
    angle step above ``max_wheel_step``, else 0. Returns the number of breaks."""
    count = 0
    for i in range(t.shape[0] - 1):
        k = 0
        if t[i + 1] - t[i] > max_step:
            k = 1
        else:
            for c in range(alpha.shape[1]):
                if abs(alpha[i + 1, c] - alpha[i, c]) > max_steering_step:
                    k = 2
            if k == 0:
                for c in range(beta.shape[1]):
                    if abs(beta[i + 1, c] - beta[i, c]) > max_wheel_step:
                        k = 3
        kind[i] = k
        if k:
            count += 1
    return count
