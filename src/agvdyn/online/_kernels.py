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
 K_DT, K_CORR_G, K_NCONST) = range(15)
#: Layout of one event row (``events``).
(E_K, E_START, E_PARAM, E_BEFORE, E_BEFORE_VAR, E_AFTER, E_AFTER_VAR, E_SIGN, E_NCOLS) = range(9)
#: CUSUM level below which its window (start row and statistics) restarts: a CUSUM that hovers
#: just above zero before a change would otherwise date the change, and fill the window, too early.
RESTART = 1.0
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
def _reset(i, theta, P, I, b, reset_var):
    """Parameter i from the rows since the change (window statistics I, b of its CUSUM), the other
    states held: prior theta_i with variance ``reset_var``; covariance of i decoupled."""
    lam = 1.0 / reset_var + I[i, i]
    rhs = theta[i] / reset_var + b[i]
    for q in range(NS):
        if q != i:
            rhs -= I[i, q] * theta[q]
    theta[i] = rhs / lam
    for q in range(NS):
        P[i, q] = 0.0
        P[q, i] = 0.0
    P[i, i] = 1.0 / lam


@_jit
def track_rows(phi, z, kind, k, theta, P, R, n_rows, g, Iw, bw, start, out_theta, out_var, out_nis, out_event,
               events, n_events):
    """Run the tracker over rows ``phi`` (N, 2), ``z`` (N,), ``kind`` (N,) with constants ``k``; the
    state (``theta`` (8,), ``P`` (8, 8), ``R`` (3,), ``n_rows`` (9,: per kind, then per coordinate),
    ``g`` (2, 2), ``Iw`` (2, 2, 8, 8), ``bw`` (2, 2, 8), ``start`` (2, 2)) is updated in place and carries over to the next log.
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
            if g[i, s] > RESTART:
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
    if gmax < 0.5 * k[K_H]:  # the noise level, frozen while a change builds up
        lam = max(1.0 / (n_rows[6 + cls] + 1.0), k[K_DT] / k[K_TAU_R])
        R[cls] += lam * (r * r - R[cls])
    n_rows[6 + cls] += 1.0
    n_rows[c - 1] += 1.0
    return _detect(n, k, theta, P, g, Iw, bw, start, reset_var, out_event, events, n_events)


@_jit
def _detect(n, k, theta, P, g, Iw, bw, start, reset_var, out_event, events, n_events):
    """A CUSUM above the threshold: reset its parameter from the rows since its start, log the event,
    restart every CUSUM."""
    fired = False
    for i in range(2):
        s = 0 if g[i, 0] >= g[i, 1] else 1
        if g[i, s] <= k[K_H]:
            continue
        fired = True
        if n_events < events.shape[0]:
            e = events[n_events]
            e[E_K], e[E_START], e[E_PARAM], e[E_SIGN] = n, start[i, s], i, 1.0 if s == 0 else -1.0
            e[E_BEFORE], e[E_BEFORE_VAR] = theta[i], P[i, i]
        _reset(i, theta, P, Iw[i, s], bw[i, s], reset_var[i])
        if n_events < events.shape[0]:
            events[n_events, E_AFTER], events[n_events, E_AFTER_VAR] = theta[i], P[i, i]
        n_events += 1
        out_event[n] |= 1 << i
    if fired:
        g[:, :] = 0.0
        Iw[:, :, :, :] = 0.0
        bw[:, :, :] = 0.0
    return n_events
