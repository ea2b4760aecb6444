"""Odometry, eq. (3): chassis velocities from the measured steering and wheel rates by least
squares over the eight rolling constraints of eq. (1)-(2), and what that least squares leaves:
the slip velocity of each contact point."""
from __future__ import annotations

import numba
import numpy as np

from agvdyn.kinematics import as_alpha, constraint_matrix_into
from agvdyn.kinematics.constraints import _rows
from agvdyn._numba_cache import drop_stale_cache
from agvdyn.kinematics import constraints

drop_stale_cache(__file__, constraints.__file__)
from agvdyn.platform import Geometry

__all__ = ["odometry", "odometry_with_slip"]


@numba.njit(cache=True)
def _odometry(l, b, a, r, alpha, alpha_dot, beta_dot, slip):  # pragma: no cover - compiled
    n = alpha.shape[0]
    out = np.empty((n, 3))
    A = np.empty((8, 9))
    M = np.empty((3, 3))
    g = np.empty(3)
    rhs = np.empty(8)
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
        if slip.shape[0] == n:  # residual of the 8 rolling constraints: slip velocity per contact point
            for w in range(4):
                lat = A[w, 0] * out[j, 0] + A[w, 1] * out[j, 1] + A[w, 2] * out[j, 2] - rhs[w]
                lon = A[4 + w, 0] * out[j, 0] + A[4 + w, 1] * out[j, 1] + A[4 + w, 2] * out[j, 2] - rhs[4 + w]
                slip[j, w] = np.sqrt(lat * lat + lon * lon)
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

    The eight rolling constraints over-determine the three chassis velocities; what the least
    squares of eq. (3) leaves, ``A(alpha) q_dot`` with the odometry's chassis velocities, is the
    slip velocity of each contact point that the measured rates imply (lateral and longitudinal;
    its norm per wheel is returned). Zero for a vehicle that rolls without slip.
    """
    alpha, alpha_dot, beta_dot = _odometry_inputs(alpha, alpha_dot, beta_dot)
    slip = np.empty((alpha.shape[0], 4))
    twist = _odometry(geom.l, geom.b, geom.a, geom.r, alpha, alpha_dot, beta_dot, slip)
    return twist, slip
