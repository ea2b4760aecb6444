"""Compiled update of the payload tracker (numba, cache=True): one pass over the rows of a log.

The algorithm, its state and constants are documented in :mod:`agvdyn.online.tracker` (the
reference of the C++ twin); this file only runs it. Fixed sizes: 8 states, 6 row kinds (3 noise classes), 4 CUSUMs.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

_jit = njit(cache=True, error_model="numpy")

#: Layout of the constants vector ``k`` of :func:`track_rows`.
(K_DELTA_M, K_DELTA_C, K_Q_M, K_Q_C, K_Q_B, K_RESET_M, K_RESET_C, K_CORR, K_GATE, K_H, K_TAU_R, K_WARM,
 K_DT, K_CORR_G, K_BIAS_VAR, K_NCONST) = range(16)
#: Layout of one event row (``events``).
(E_K, E_START, E_PARAM, E_BEFORE, E_BEFORE_VAR, E_AFTER, E_AFTER_VAR, E_SIGN, E_NCOLS) = range(9)
#: CUSUM level below which its window (start row and statistics) restarts: a CUSUM that hovers
#: just above zero before a change would otherwise date the change, and fill the window, too early.
RESTART = 1.0
#: A row bias learnt from fewer than YOUNG_WARMUPS x warm_rows rows of its kind may have absorbed part
#: of a change (its kind first driven after it): a reset re-estimates it with the change.
YOUNG_WARMUPS = 10.0
NS = 8  # states: m_ch, C_ch, bias of the rows of x_ch+, x_ch-, y_ch+, y_ch-, gamma_ch+, gamma_ch-


@_jit
def _add_row(I, b, f, z, w):
    """I += f f^T w, b += f z w (one CUSUM's window statistics)."""
    for p in range(NS):
        b[p] += f[p] * z * w
        for q in range(NS):
            I[p, q] += f[p] * f[q] * w


@_jit
def _joseph(P, K, f, r_eff, tmp):
    """P <- (I - K f^T) P (I - K f^T)^T + K r_eff K^T (valid for any gain K)."""
    for p in range(NS):
        for q in range(NS):
            a = 0.0
            for s in range(NS):
                a += ((1.0 if p == s else 0.0) - K[p] * f[s]) * P[s, q]
            tmp[p, q] = a
    for p in range(NS):
        for q in range(NS):
            a = 0.0
            for s in range(NS):
                a += tmp[p, s] * ((1.0 if q == s else 0.0) - K[q] * f[s])
            P[p, q] = a + K[p] * r_eff * K[q]


@_jit
def _reset_payload(theta, P, I, b, reset_var, n_rows, young, bias_var):
    """A payload change: m_ch, C_ch and the young row biases the window saw (kind rows < ``young``)
    re-estimated together from a CUSUM's window (statistics I, b): priors at their values with variances
    ``reset_var`` (2,) and ``bias_var``; the other biases held; the covariance of the re-estimated
    states is the inverse of the normal matrix, decoupled from the rest."""
    sel = np.zeros(NS, dtype=np.bool_)
    sel[0] = True
    sel[1] = True
    for j in range(2, NS):
        sel[j] = I[j, j] > 0.0 and n_rows[j - 2] < young
    A = np.zeros((NS, NS))
    r = np.zeros(NS)
    for p in range(NS):
        if not sel[p]:
            A[p, p] = 1.0
            continue
        prior = 1.0 / (reset_var[p] if p < 2 else bias_var)
        r[p] = theta[p] * prior + b[p]
        for q in range(NS):
            if sel[q]:
                A[p, q] = I[p, q]
            else:
                r[p] -= I[p, q] * theta[q]
        A[p, p] += prior
    Ainv = np.zeros((NS, NS))
    _inverse_spd(A, Ainv)
    x = np.zeros(NS)
    for p in range(NS):
        a = 0.0
        for q in range(NS):
            a += Ainv[p, q] * r[q]
        x[p] = a
    for p in range(NS):
        if sel[p]:
            theta[p] = x[p]
            for q in range(NS):
                P[p, q] = 0.0
                P[q, p] = 0.0
    for p in range(NS):
        if sel[p]:
            for q in range(NS):
                if sel[q]:
                    P[p, q] = Ainv[p, q]


@_jit
def _inverse_spd(A, out):
    """out = A^-1 of a symmetric positive definite (NS, NS) matrix by Gauss-Jordan without pivoting."""
    M = A.copy()
    for p in range(NS):
        for q in range(NS):
            out[p, q] = 1.0 if p == q else 0.0
    for c in range(NS):
        d = M[c, c]
        for q in range(NS):
            M[c, q] /= d
            out[c, q] /= d
        for p in range(NS):
            if p != c:
                f = M[p, c]
                if f != 0.0:
                    for q in range(NS):
                        M[p, q] -= f * M[c, q]
                        out[p, q] -= f * out[c, q]


@_jit
def track_rows(phi, z, kind, k, theta, P, R, n_rows, g, Iw, bw, start, out_theta, out_var, out_nis, out_event,
               events, n_events):
    """Run the tracker over rows ``phi`` (N, 2), ``z`` (N,), ``kind`` (N,) with constants ``k``; the
    state (``theta`` (8,), ``P`` (8, 8), ``R`` (3,), ``n_rows`` (9,: per kind, then per coordinate),
    ``g`` (2, 2), ``Iw`` (2, 2, 8, 8), ``bw`` (2, 2, 8), ``start`` (2, 2)) is updated in place and carries
    over to the next log.
    Writes per sample the estimates, variances, NIS (NaN without a row) and event flags (bit 0: m_ch,
    bit 1: C_ch); events as rows of ``events`` from ``n_events``; returns the new event count."""
    f = np.zeros(NS)
    K = np.zeros(NS)
    Pf = np.zeros(NS)
    tmp = np.zeros((NS, NS))
    delta = (k[K_DELTA_M], k[K_DELTA_C])
    q = (k[K_Q_M] * k[K_DT], k[K_Q_C] * k[K_DT])
    reset_var = (k[K_RESET_M], k[K_RESET_C])
    for n in range(phi.shape[0]):
        out_event[n] = 0
        c = kind[n]
        if c > 0:
            n_events = _update(n, phi[n, 0], phi[n, 1], z[n], c, k, delta, q, reset_var, theta, P, R, n_rows, g,
                               Iw, bw, start, f, K, Pf, tmp, out_nis, out_event, events, n_events)
        else:
            out_nis[n] = math.nan
        for p in range(NS):
            out_theta[n, p] = theta[p]
            out_var[n, p] = P[p, p]
    return n_events


@_jit
def _update(n, phi_m, phi_c, z, c, k, delta, q, reset_var, theta, P, R, n_rows, g, Iw, bw, start, f, K, Pf, tmp,
            out_nis, out_event, events, n_events):
    """One row: prediction, innovation, CUSUMs, gated update, noise estimate, detection and reset."""
    j = 1 + c  # the bias state of this kind of row
    cls = (c - 1) // 2  # its coordinate: noise class
    for p in range(NS):
        f[p] = 0.0
    f[0], f[1], f[j] = phi_m, phi_c, 1.0
    r_c = R[cls]
    r_eff = r_c * (k[K_CORR_G] if cls == 2 else k[K_CORR])
    noise = math.sqrt(r_c)
    excited = (abs(phi_m) * delta[0] >= k[K_GATE] * noise, abs(phi_c) * delta[1] >= k[K_GATE] * noise)
    for i in range(2):  # random walk, only in the excited directions (no wind-up), capped at the reset level
        if excited[i]:
            P[i, i] = min(P[i, i] + q[i], reset_var[i])
    P[j, j] += k[K_Q_B] * k[K_DT]
    r = z
    for p in range(NS):
        r -= f[p] * theta[p]
        a = 0.0
        for s in range(NS):
            a += P[p, s] * f[s]
        Pf[p] = a
    fPf = 0.0
    for p in range(NS):
        fPf += f[p] * Pf[p]
    out_nis[n] = r * r / (fPf + r_c)
    warm = n_rows[c - 1] >= k[K_WARM]  # rows of this kind (its bias has settled)
    tested = warm and excited[1 if cls == 2 else 0]  # this row's own CUSUMs run on it
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
                    _add_row(Iw[i, s], bw[i, s], f, z, 1.0 / r_eff)
            gmax = max(gmax, g[i, s])
    s_tot = fPf + r_eff
    for p in range(NS):
        K[p] = Pf[p] / s_tot
    for i in range(2):
        if not excited[i]:
            K[i] = 0.0  # directional update: nothing learnt along an unexcited parameter
    _joseph(P, K, f, r_eff, tmp)
    for p in range(NS):
        theta[p] += K[p] * r
    if tested and gmax < 0.5 * k[K_H]:  # the noise level: from rows the detector tests, none while a change builds up
        lam = max(1.0 / (n_rows[6 + cls] + 1.0), k[K_DT] / k[K_TAU_R])
        R[cls] += lam * (r * r - R[cls])
    n_rows[6 + cls] += 1.0
    n_rows[c - 1] += 1.0
    return _detect(n, k, theta, P, n_rows, g, Iw, bw, start, reset_var, out_event, events, n_events)


@_jit
def _detect(n, k, theta, P, n_rows, g, Iw, bw, start, reset_var, out_event, events, n_events):
    """CUSUMs above the threshold: a payload change; m_ch and C_ch reset from the window of the highest
    of them (:func:`_reset_payload`), one event per parameter whose CUSUM fired; every CUSUM restarts."""
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
                   k[K_BIAS_VAR])
    for m in range(n0, min(n_events, events.shape[0])):
        i = int(events[m, E_PARAM])
        events[m, E_AFTER], events[m, E_AFTER_VAR] = theta[i], P[i, i]
    g[:, :] = 0.0
    Iw[:, :, :, :] = 0.0
    bw[:, :, :] = 0.0
    return n_events
