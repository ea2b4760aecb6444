"""Odometry, eq. (3): chassis velocities from the measured steering and wheel rates by least
squares over the eight rolling constraints of eq. (1)-(2), and the slip speed of each contact point.

Slip, leave one wheel out: the residual of the least squares over all eight constraints spreads a
single slipping wheel's slip over every wheel (a share of 0.4 to 0.7 on its own). Instead, for
each wheel j the chassis velocity is fitted to the six constraints of the other three wheels; the
j whose fit leaves the others most consistent (smallest sum of their squared residuals ``S_j``)
is taken as the slipping one, and its own residual ``e_j`` under that fit is its slip, debiased
by what the others' inconsistency explains: ``sqrt(max(|e_j|^2 - S_j, 0))`` (a slip-free row with
equal noise on every constraint has ``E|e_j|^2 ~ E S_j``, so both shrink to about zero together).
The other wheels get their residuals under the same fit. The deletion formulas of least squares
(``e_(j) = (I - H_jj)^-1 e_j``, ``S_j = |e|^2 - e_j . e_(j)`` with the 2x2 block ``H_jj`` of the hat
matrix) give all four fits from the full one, per row, without a loop over candidates' solves.
Two wheels slipping at once are both reported, with less exact speeds."""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit
from agvdyn.kinematics import as_alpha, constraint_matrix_into
from agvdyn.kinematics.constraints import _rows
from agvdyn._numba_cache import drop_stale_cache
from agvdyn.kinematics import constraints

drop_stale_cache(__file__, constraints.__file__)
from agvdyn.platform import Geometry

__all__ = ["odometry", "odometry_with_slip", "wheel_slip_row"]


@njit(cache=True, nogil=True, inline="always")
def wheel_slip_row(A, P, rhs, e, slip, j):  # pragma: no cover - compiled
    """Slip speed of each contact point of row j (leave one wheel out, see the module docstring)
    into ``slip[j]``: ``A`` (8, >= 3) rows of eq. (1)-(2) (lateral rows 0-3, longitudinal 4-7, wheel
    order fl, rl, fr, rr; chassis columns first), ``P`` (3, 3) ``(A_ch^T A_ch)^-1``, ``rhs`` (8,)
    ``-(A_alpha alpha_dot + A_beta beta_dot)``, ``e`` (8,) scratch."""
    g0 = g1 = g2 = 0.0
    for k in range(8):
        g0 += A[k, 0] * rhs[k]
        g1 += A[k, 1] * rhs[k]
        g2 += A[k, 2] * rhs[k]
    v0 = P[0, 0] * g0 + P[0, 1] * g1 + P[0, 2] * g2
    v1 = P[1, 0] * g0 + P[1, 1] * g1 + P[1, 2] * g2
    v2 = P[2, 0] * g0 + P[2, 1] * g1 + P[2, 2] * g2
    sse = 0.0
    for k in range(8):
        e[k] = A[k, 0] * v0 + A[k, 1] * v1 + A[k, 2] * v2 - rhs[k]
        sse += e[k] * e[k]
    best = np.inf
    out = u0 = u1 = d0 = d1 = d2 = 0.0
    for w in range(4):  # the fit without wheel w: residual u = (I - H_ww)^-1 e_w, others' S_w
        p0 = P[0, 0] * A[w, 0] + P[0, 1] * A[w, 1] + P[0, 2] * A[w, 2]
        p1 = P[1, 0] * A[w, 0] + P[1, 1] * A[w, 1] + P[1, 2] * A[w, 2]
        p2 = P[2, 0] * A[w, 0] + P[2, 1] * A[w, 1] + P[2, 2] * A[w, 2]
        q0 = P[0, 0] * A[4 + w, 0] + P[0, 1] * A[4 + w, 1] + P[0, 2] * A[4 + w, 2]
        q1 = P[1, 0] * A[4 + w, 0] + P[1, 1] * A[4 + w, 1] + P[1, 2] * A[4 + w, 2]
        q2 = P[2, 0] * A[4 + w, 0] + P[2, 1] * A[4 + w, 1] + P[2, 2] * A[4 + w, 2]
        m11 = 1.0 - (A[w, 0] * p0 + A[w, 1] * p1 + A[w, 2] * p2)
        m12 = -(A[w, 0] * q0 + A[w, 1] * q1 + A[w, 2] * q2)
        m22 = 1.0 - (A[4 + w, 0] * q0 + A[4 + w, 1] * q1 + A[4 + w, 2] * q2)
        inv = 1.0 / (m11 * m22 - m12 * m12)
        a0 = (m22 * e[w] - m12 * e[4 + w]) * inv
        a1 = (m11 * e[4 + w] - m12 * e[w]) * inv
        others = sse - (e[w] * a0 + e[4 + w] * a1)
        if others < best:
            best, out, u0, u1 = others, w, a0, a1
            d0, d1, d2 = p0 * a0 + q0 * a1, p1 * a0 + q1 * a1, p2 * a0 + q2 * a1  # v_(w) - v
    for w in range(4):
        if w == out:
            slip[j, w] = np.sqrt(max(u0 * u0 + u1 * u1 - max(best, 0.0), 0.0))
        else:
            lat = e[w] + A[w, 0] * d0 + A[w, 1] * d1 + A[w, 2] * d2
            lon = e[4 + w] + A[4 + w, 0] * d0 + A[4 + w, 1] * d1 + A[4 + w, 2] * d2
            slip[j, w] = np.sqrt(lat * lat + lon * lon)


@njit(cache=True)
def _odometry(l, b, a, r, alpha, alpha_dot, beta_dot, slip):  # pragma: no cover - compiled
    n = alpha.shape[0]
    out = np.empty((n, 3))
    A = np.empty((8, 9))
    M = np.empty((3, 3))
    g = np.empty(3)
    rhs = np.empty(8)
    e = np.empty(8)
    P = np.empty((3, 3))
    radii = np.full(4, r)
    for j in range(n):
        constraint_matrix_into(l, b, a, radii, alpha[j, 0], alpha[j, 1], A)
        M[:, :] = 0.0
        g[:] = 0.0
        for row in range(8):
            rhs[row] = -(A[row, 3] * alpha_dot[j, 0] + A[row, 4] * alpha_dot[j, 1])
            for w in range(4):
                rhs[row] -= A[row, 5 + w] * beta_dot[j, w]
            for p in range(3):
                g[p] += A[row, p] * rhs[row]
                for q in range(3):
                    M[p, q] += A[row, p] * A[row, q]
        # 3 x 3 symmetric solve by cofactors (A_ch has full column rank for every alpha)
        c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
        c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
        c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
        c11 = M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]
        c12 = M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]
        c22 = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
        det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
        out[j, 0] = (c00 * g[0] + c01 * g[1] + c02 * g[2]) / det
        out[j, 1] = (c01 * g[0] + c11 * g[1] + c12 * g[2]) / det
        out[j, 2] = (c02 * g[0] + c12 * g[1] + c22 * g[2]) / det
        if slip.shape[0] == n:  # slip speed per contact point, leave one wheel out
            P[0, 0], P[0, 1], P[0, 2] = c00 / det, c01 / det, c02 / det
            P[1, 0], P[1, 1], P[1, 2] = c01 / det, c11 / det, c12 / det
            P[2, 0], P[2, 1], P[2, 2] = c02 / det, c12 / det, c22 / det
            wheel_slip_row(A, P, rhs, e, slip, j)
    return out


def _odometry_inputs(alpha, alpha_dot, beta_dot):
    alpha = np.ascontiguousarray(as_alpha(alpha))
    n = alpha.shape[0]
    alpha_dot = np.ascontiguousarray(_rows(alpha_dot, n, 2, "alpha_dot"))
    beta_dot = np.ascontiguousarray(_rows(beta_dot, n, 4, "beta_dot"))
    return alpha, alpha_dot, beta_dot


def odometry(geom: Geometry, alpha, alpha_dot, beta_dot) -> np.ndarray:
    """Chassis velocities ``(N, 3)`` = (v_x, v_y, omega) from measured angles and rates, eq. (3).

    ``q_ch_dot = -A_ch^+ (A_alpha alpha_dot + A_beta beta_dot)`` (least squares over all 8 rows).
    """
    alpha, alpha_dot, beta_dot = _odometry_inputs(alpha, alpha_dot, beta_dot)
    return _odometry(geom.l, geom.b, geom.a, geom.r, alpha, alpha_dot, beta_dot, np.empty((0, 4)))


def odometry_with_slip(geom: Geometry, alpha, alpha_dot, beta_dot) -> tuple[np.ndarray, np.ndarray]:
    """Chassis velocities of eq. (3) ``(N, 3)`` and the slip speed of each wheel ``(N, 4)`` (m/s).

    The eight rolling constraints over-determine the three chassis velocities. The chassis
    velocities are the least squares of eq. (3) over all eight; the slip speed of each contact
    point (norm of its lateral and longitudinal slip velocity ``A(alpha) q_dot``) is taken with one
    wheel left out, so that a single slipping wheel shows its own slip, not a share of it spread
    over all four (module docstring). Zero for a vehicle that rolls without slip.

    >>> import numpy as np
    >>> from agvdyn.platform import PROTOTYPE
    >>> v, s = odometry_with_slip(PROTOTYPE, np.zeros((1, 2)), np.zeros((1, 2)), [[10.0, 10.0, 10.4, 10.0]])
    >>> np.round(v[0], 3).tolist(), np.round(s[0], 3).tolist()   # fr spins 0.04 m/s faster
    ([1.01, 0.0, 0.008], [0.0, 0.0, 0.04, 0.0])
    """
    alpha, alpha_dot, beta_dot = _odometry_inputs(alpha, alpha_dot, beta_dot)
    slip = np.empty((alpha.shape[0], 4))
    twist = _odometry(geom.l, geom.b, geom.a, geom.r, alpha, alpha_dot, beta_dot, slip)
    return twist, slip
