"""Compiled update of the payload tracker (numba, cache=True): one pass over the rows of a log.

The algorithm, its state and constants are documented in :mod:`agvdyn.online.tracker` (the
reference of the C++ twin); this file only runs it. Sizes: 8 states (``NS``; 9 with the centre-of-mass
offset, ``NS + 1``: the size of ``theta`` says which), 8 row kinds (6 biases, 4 noise classes), 4 CUSUMs.
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn._jit import njit

_jit = njit(cache=True, error_model="numpy")

#: Layout of the constants vector ``k`` of :func:`track_rows`.
(K_DELTA_M, K_DELTA_C, K_Q_M, K_Q_C, K_Q_B, K_RESET_M, K_RESET_C, K_CORR, K_GATE, K_H, K_TAU_R, K_WARM,
 K_DT, K_CORR_G, K_BIAS_VAR, K_DELTA_Y, K_Q_Y, K_RESET_Y, K_TWIN_VAR, K_NCONST) = range(20)
#: Layout of one event row (``events``).
(E_K, E_START, E_PARAM, E_BEFORE, E_BEFORE_VAR, E_AFTER, E_AFTER_VAR, E_SIGN, E_NCOLS) = range(9)
#: CUSUM level below which its window (start row and statistics) restarts: a CUSUM that hovers
#: just above zero before a change would otherwise date the change, and fill the window, too early.
RESTART = 1.0
#: A row bias learnt from fewer than YOUNG_WARMUPS x warm_rows rows of its kind may have absorbed part
#: of a change (its kind first driven after it): a reset re-estimates it with the change.
YOUNG_WARMUPS = 10.0
NS = 8  # states: m_ch, C_ch, bias of the rows of x_ch+, x_ch-, y_ch+, y_ch-, gamma_ch+, gamma_ch-
#: Index of the state m_ch y_c (tracked with the centre-of-mass offset: ``NS + 1`` states).
OFFSET = NS
OFFSET_STATES = NS + 1
#: y_c's variance counts as informed (a finite std is reported) once below this fraction of its prior.
INFORMED = 1.0 - 1e-6
#: Row kinds (codes 1..KINDS of agvdyn.online.rows.ROW_KINDS; 7, 8: the car-like x_ch rows) and noise classes
#: (x_ch straight, y_ch, gamma_ch, x_ch car-like): ``n_rows`` holds the rows per kind, then per class.
KINDS = 8
CLASSES = 4
#: ``n_rows`` after the rows per kind and per class: the *tested* rows per kind (rows a CUSUM ran on: the kind
#: warm and its coordinate's parameter excited); a bias with fewer than ``warm`` of them is unverified.
TESTED = KINDS + CLASSES
COUNTS = TESTED + KINDS
CAR_LIKE = 3  # the noise class of the car-like rows (kinds 7, 8: the biases of x_ch+, x_ch-)


@_jit
def _add_row(I, b, f, z, w, ns):
    """I += f f^T w, b += f z w (one CUSUM's window statistics)."""
    for p in range(ns):
        b[p] += f[p] * z * w
        for q in range(ns):
            I[p, q] += f[p] * f[q] * w


@_jit
def _joseph(P, K, f, r_eff, tmp, ns):
    """P <- (I - K f^T) P (I - K f^T)^T + K r_eff K^T (valid for any gain K)."""
    for p in range(ns):
        for q in range(ns):
            a = 0.0
            for s in range(ns):
                a += ((1.0 if p == s else 0.0) - K[p] * f[s]) * P[s, q]
            tmp[p, q] = a
    for p in range(ns):
        for q in range(ns):
            a = 0.0
            for s in range(ns):
                a += tmp[p, s] * ((1.0 if q == s else 0.0) - K[q] * f[s])
            P[p, q] = a + K[p] * r_eff * K[q]


@_jit
def _reset_payload(theta, P, I, b, reset_var, n_rows, young, bias_var, ns):
    """A payload change: m_ch, C_ch (and m_ch y_c when tracked) and the young row biases the window saw
    (rows of its kinds < ``young``) re-estimated together from a CUSUM's window (statistics I, b): priors at
    their values with variances ``reset_var`` (m_ch, C_ch, m_ch y_c) and ``bias_var``; the other biases
    held; the covariance of the re-estimated states is the inverse of the normal matrix, decoupled
    from the rest."""
    sel = np.zeros(ns, dtype=np.bool_)
    sel[0] = True
    sel[1] = True
    for j in range(2, NS):
        seen = n_rows[j - 2] + (n_rows[j + 4] if j < 4 else 0.0)  # x_ch biases: straight and car-like rows
        sel[j] = I[j, j] > 0.0 and seen < young
        tested = n_rows[TESTED + j - 2] + (n_rows[TESTED + j + 4] if j < 4 else 0.0)
        if not sel[j] and seen > 0.0 and tested < young / YOUNG_WARMUPS:
            _unknown_bias(P, j, bias_var, ns)  # learnt from rows no CUSUM checked: it may hold the change
    if ns > NS:
        sel[OFFSET] = True
    A = np.zeros((ns, ns))
    r = np.zeros(ns)
    for p in range(ns):
        if not sel[p]:
            A[p, p] = 1.0
            continue
        prior = 1.0 / (reset_var[p] if p < 2 else (reset_var[2] if p == OFFSET else bias_var))
        r[p] = theta[p] * prior + b[p]
        for q in range(ns):
            if sel[q]:
                A[p, q] = I[p, q]
            else:
                r[p] -= I[p, q] * theta[q]
        A[p, p] += prior
    Ainv = np.zeros((ns, ns))
    _inverse_spd(A, Ainv, ns)
    x = np.zeros(ns)
    for p in range(ns):
        a = 0.0
        for q in range(ns):
            a += Ainv[p, q] * r[q]
        x[p] = a
    for p in range(ns):
        if sel[p]:
            theta[p] = x[p]
            for q in range(ns):
                P[p, q] = 0.0
                P[q, p] = 0.0
    for p in range(ns):
        if sel[p]:
            for q in range(ns):
                if sel[q]:
                    P[p, q] = Ainv[p, q]


@_jit
def _unknown_bias(P, j, bias_var, ns):
    """Bias ``j`` treated as unknown: its variance back to the prior ``bias_var``, uncorrelated (value kept)."""
    for q in range(ns):
        P[j, q] = 0.0
        P[q, j] = 0.0
    P[j, j] = bias_var


@_jit
def _twin_bias(theta, P, n_rows, c, j, warm, twin_var, ns):
    """At the first row of kind ``c`` (1..6) whose twin (the same coordinate, the other sign of its velocity)
    is warm: its bias starts at the twin's, variance the twin's plus ``twin_var``, uncorrelated. Returns
    whether the kind counts as warm through its twin (its CUSUMs then run from this row on)."""
    if c > 6:
        return False
    twin = c + 1 if c % 2 == 1 else c - 1
    if n_rows[twin - 1] < warm:
        return False
    if n_rows[c - 1] == 0.0 and (c > 2 or n_rows[c + 5] == 0.0):  # the bias's first row (x_ch: car-like ones too)
        var = P[1 + twin, 1 + twin] + twin_var
        theta[j] = theta[1 + twin]
        _unknown_bias(P, j, var, ns)
    return True


@_jit
def _inverse_spd(A, out, ns):
    """out = A^-1 of a symmetric positive definite (ns, ns) matrix by Gauss-Jordan without pivoting."""
    M = A.copy()
    for p in range(ns):
        for q in range(ns):
            out[p, q] = 1.0 if p == q else 0.0
    for c in range(ns):
        d = M[c, c]
        for q in range(ns):
            M[c, q] /= d
            out[c, q] /= d
        for p in range(ns):
            if p != c:
                f = M[p, c]
                if f != 0.0:
                    for q in range(ns):
                        M[p, q] -= f * M[c, q]
                        out[p, q] -= f * out[c, q]


@_jit
def offset_estimate(theta, P, reset_var_y):
    """``(y_c, std)`` from the states m_ch and m_ch y_c: ``y_c = s / m`` with the delta-method std
    ``sqrt(g^T P g)``, ``g = (-s / m^2, 1 / m)``; the std is inf while the variance of ``s`` is at its
    prior ``reset_var_y`` or above (no row has informed it since the start or the last reset)."""
    m, s = theta[0], theta[OFFSET]
    y = s / m
    if not P[OFFSET, OFFSET] < INFORMED * reset_var_y:
        return y, math.inf
    g0 = -s / (m * m)
    g1 = 1.0 / m
    var = g0 * g0 * P[0, 0] + 2.0 * g0 * g1 * P[0, OFFSET] + g1 * g1 * P[OFFSET, OFFSET]
    return y, math.sqrt(max(var, 0.0))


@_jit
def track_rows(phi, z, kind, k, theta, P, R, n_rows, g, Iw, bw, start, out_theta, out_var, out_nis, out_event,
               out_offset, events, n_events):
    """Run the tracker over rows ``phi`` (N, 2; (N, 3) with the m_ch y_c column), ``z`` (N,), ``kind``
    (N,) with constants ``k``; the state (``theta`` (ns,), ``P`` (ns, ns), ``R`` (4,: per noise class),
    ``n_rows`` (12,: per kind, then per noise class), ``g`` (2, 2), ``Iw`` (2, 2, ns, ns), ``bw`` (2, 2, ns), ``start``
    (2, 2); ns = 8, or 9 with the centre-of-mass offset) is updated in place and carries over to the
    next log.
    Writes per sample the estimates, variances, NIS (NaN without a row), event flags (bit 0: m_ch,
    bit 1: C_ch) and, with the offset, ``out_offset`` (N, 2) = (y_c, its std: :func:`offset_estimate`);
    events as rows of ``events`` from ``n_events``; returns the new event count."""
    if theta.shape[0] == NS:  # the size as a compile-time constant: fixed-size loops
        return _track(phi, z, kind, k, theta, P, R, n_rows, g, Iw, bw, start, out_theta, out_var, out_nis, out_event,
                      out_offset, events, n_events, NS)
    return _track(phi, z, kind, k, theta, P, R, n_rows, g, Iw, bw, start, out_theta, out_var, out_nis, out_event,
                  out_offset, events, n_events, OFFSET_STATES)


@_jit
def _track(phi, z, kind, k, theta, P, R, n_rows, g, Iw, bw, start, out_theta, out_var, out_nis, out_event,
           out_offset, events, n_events, ns):
    """:func:`track_rows` with ``ns`` states (a literal)."""
    f = np.zeros(ns)
    K = np.zeros(ns)
    Pf = np.zeros(ns)
    tmp = np.zeros((ns, ns))
    delta = (k[K_DELTA_M], k[K_DELTA_C], k[K_DELTA_Y])
    q = (k[K_Q_M] * k[K_DT], k[K_Q_C] * k[K_DT], k[K_Q_Y] * k[K_DT])
    reset_var = (k[K_RESET_M], k[K_RESET_C], k[K_RESET_Y])
    for n in range(phi.shape[0]):
        out_event[n] = 0
        c = kind[n]
        if c > 0:
            phi_y = phi[n, 2] if ns > NS else 0.0
            n_events = _update(n, phi[n, 0], phi[n, 1], phi_y, z[n], c, k, delta, q, reset_var, theta, P, R, n_rows,
                               g, Iw, bw, start, f, K, Pf, tmp, out_nis, out_event, events, n_events, ns)
        else:
            out_nis[n] = math.nan
        for p in range(ns):
            out_theta[n, p] = theta[p]
            out_var[n, p] = P[p, p]
        if ns > NS:
            out_offset[n, 0], out_offset[n, 1] = offset_estimate(theta, P, reset_var[2])
    return n_events


@_jit
def _predict(P, f, phi_m, phi_c, phi_y, noise, k, delta, q, reset_var, ns):
    """Information gating and the random walk of the payload parameters: ``(excited m_ch, excited C_ch)`` and
    excited m_ch y_c (with ``ns`` > 8, whose entry of ``f`` it sets); the variance of an excited one grows
    by its ``q``, capped at its reset level (no wind-up along unexcited directions)."""
    excited = (abs(phi_m) * delta[0] >= k[K_GATE] * noise, abs(phi_c) * delta[1] >= k[K_GATE] * noise)
    for i in range(2):
        if excited[i]:
            P[i, i] = min(P[i, i] + q[i], reset_var[i])
    excited_y = False
    if ns > NS:  # m_ch y_c: the same gating and random walk (its column is nonzero in car-like rows only)
        f[OFFSET] = phi_y
        excited_y = abs(phi_y) * delta[2] >= k[K_GATE] * noise
        if excited_y:
            P[OFFSET, OFFSET] = min(P[OFFSET, OFFSET] + q[2], reset_var[2])
    return excited, excited_y


@_jit
def _update(n, phi_m, phi_c, phi_y, z, c, k, delta, q, reset_var, theta, P, R, n_rows, g, Iw, bw, start, f, K, Pf,
            tmp, out_nis, out_event, events, n_events, ns):
    """One row: prediction, innovation, CUSUMs, gated update, noise estimate, detection and reset."""
    j = 1 + c if c <= 6 else c - 5  # the bias state of this kind of row (car-like x_ch rows: the straight ones')
    cls = (c - 1) // 2 if c <= 6 else CAR_LIKE  # its noise class: x_ch straight, y_ch, gamma_ch, x_ch car-like
    for p in range(ns):
        f[p] = 0.0
    f[0], f[1], f[j] = phi_m, phi_c, 1.0
    twin_warm = _twin_bias(theta, P, n_rows, c, j, k[K_WARM], k[K_TWIN_VAR], ns)
    r_c = R[cls]
    r_eff = r_c * (k[K_CORR_G] if cls == 2 else k[K_CORR])
    excited, excited_y = _predict(P, f, phi_m, phi_c, phi_y, math.sqrt(r_c), k, delta, q, reset_var, ns)
    P[j, j] += k[K_Q_B] * k[K_DT]
    r = z
    for p in range(ns):
        r -= f[p] * theta[p]
        a = 0.0
        for s in range(ns):
            a += P[p, s] * f[s]
        Pf[p] = a
    fPf = 0.0
    for p in range(ns):
        fPf += f[p] * Pf[p]
    out_nis[n] = r * r / (fPf + r_c)
    warm = n_rows[c - 1] >= k[K_WARM] or twin_warm  # rows of this kind (its bias has settled), or of its twin
    # the noise class learns from the rows of its own test (car-like rows: also the C_ch-excited ones, whose
    # yaw misfit, e.g. tyre scrub, would otherwise pull C_ch with the straight rows' weight)
    tested = warm and (excited[1 if cls == 2 else 0] or (cls == CAR_LIKE and excited[1]))
    gmax = 0.0
    for i in range(2):
        for s in range(2):
            if warm and excited[i] and (cls == 2) == (i == 1):  # m_ch from translation rows, C_ch from rotation
                sign = 1.0 if s == 0 else -1.0
                fi = phi_m if i == 0 else phi_c
                new = g[i, s] + (sign * delta[i] * fi * r - 0.5 * (delta[i] * fi) ** 2) / r_eff
                if g[i, s] <= RESTART and new > RESTART:  # the window: rows since g last was <= RESTART
                    start[i, s] = n
                    Iw[i, s, :, :] = 0.0
                    bw[i, s, :] = 0.0
                g[i, s] = max(new, 0.0)
                if g[i, s] > RESTART:  # the window holds the rows its CUSUM ran on
                    _add_row(Iw[i, s], bw[i, s], f, z, 1.0 / r_eff, ns)
            gmax = max(gmax, g[i, s])
    s_tot = fPf + r_eff
    for p in range(ns):
        K[p] = Pf[p] / s_tot
    for i in range(2):
        if not excited[i]:
            K[i] = 0.0  # directional update: nothing learnt along an unexcited parameter
    if ns > NS and not excited_y:
        K[OFFSET] = 0.0
    _joseph(P, K, f, r_eff, tmp, ns)
    for p in range(ns):
        theta[p] += K[p] * r
    # the noise level: from rows the detector tests, none while a change builds up (any CUSUM above h / 2; for
    # rotation rows, which fit to their noise on both plants, while C_ch's window is open: above RESTART)
    if tested and gmax < 0.5 * k[K_H] and not (cls == 2 and max(g[1, 0], g[1, 1]) > RESTART):
        lam = max(1.0 / (n_rows[KINDS + cls] + 1.0), k[K_DT] / k[K_TAU_R])
        R[cls] += lam * (r * r - R[cls])
    n_rows[KINDS + cls] += 1.0
    n_rows[c - 1] += 1.0
    if warm and excited[1 if cls == 2 else 0]:
        n_rows[TESTED + c - 1] += 1.0  # a row its CUSUM ran on
    return _detect(n, k, theta, P, n_rows, g, Iw, bw, start, reset_var, out_event, events, n_events, ns)


@_jit
def _detect(n, k, theta, P, n_rows, g, Iw, bw, start, reset_var, out_event, events, n_events, ns):
    """CUSUMs above the threshold: a payload change; m_ch, C_ch (and m_ch y_c) reset from the window of the
    highest of them (:func:`_reset_payload`), one event per parameter whose CUSUM fired; every CUSUM restarts."""
    best, best_s, n0 = -1, 0, n_events
    for i in range(2):
        s = 0 if g[i, 0] >= g[i, 1] else 1
        if g[i, s] <= k[K_H]:
            continue
        if best < 0 or g[i, s] > g[best, best_s]:
            best, best_s = i, s
        if n_events < events.shape[0]:
            e = events[n_events]
            e[E_K], e[E_START], e[E_PARAM], e[E_SIGN] = n, start[i, s], i, 1.0 if s == 0 else -1.0
            e[E_BEFORE], e[E_BEFORE_VAR] = theta[i], P[i, i]
        n_events += 1
        out_event[n] |= 1 << i
    if best < 0:
        return n_events
    _reset_payload(theta, P, Iw[best, best_s], bw[best, best_s], reset_var, n_rows, YOUNG_WARMUPS * k[K_WARM],
                   k[K_BIAS_VAR], ns)
    for m in range(n0, min(n_events, events.shape[0])):
        i = int(events[m, E_PARAM])
        events[m, E_AFTER], events[m, E_AFTER_VAR] = theta[i], P[i, i]
    g[:, :] = 0.0
    Iw[:, :, :, :] = 0.0
    bw[:, :, :] = 0.0
    return n_events
