"""Kinematic models H_k of the motion modes, eq. (4), (10)-(13): admissible velocities
``q_dot = H_k s_dot``, their time derivative and the joint motion of a planned ``s(t)``.

Conventions as in :mod:`agvdyn.kinematics.constraints` (sample axis first).
"""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit
from agvdyn.kinematics.constraints import (
    MODE_TOLERANCE,
    N_Q,
    _SIDE,
    Mode,
    _rows,
    as_alpha,
    check_mode,
    max_virtual_angle,
    nominal_steering,
    steering_from_virtual_derivatives,
    virtual_from_steering,
    wheel_headings,
)
from agvdyn.platform import Geometry

def _wheel_rates(geom: Geometry, theta: np.ndarray, twist: np.ndarray, alpha_dot: np.ndarray) -> np.ndarray:
    """beta_dot ``(N, 4)`` that satisfies the longitudinal constraints for a chassis twist and steering rates."""
    cx, cy = geom.steering_axes.T
    vx = twist[:, 0:1] - twist[:, 2:3] * cy
    vy = twist[:, 1:2] + twist[:, 2:3] * cx
    theta_dot = alpha_dot[:, _SIDE] * geom.heading_sign
    return (np.cos(theta) * vx + np.sin(theta) * vy - geom.side_sign * geom.a * (twist[:, 2:3] + theta_dot)) / geom.r


def _column(geom: Geometry, theta: np.ndarray, twist: np.ndarray, alpha_dot: np.ndarray) -> np.ndarray:
    """One admissible velocity q_dot ``(N, 9)`` from a chassis twist and steering rates."""
    return np.concatenate([twist, alpha_dot, _wheel_rates(geom, theta, twist, alpha_dot)], axis=1)


def _constant_model(geom: Geometry, mode: Mode) -> np.ndarray:
    """H_k ``(9, n_k)`` of the modes whose H_k is constant (1, 3, 4, straight)."""
    if mode is Mode.PARKING:
        theta = np.zeros((1, 4))  # wheel rates of pure steering do not depend on theta
        cols = [_column(geom, theta, np.zeros((1, 3)), np.eye(2)[[i]]) for i in range(2)]
        return np.concatenate(cols, axis=0).T
    theta = wheel_headings(geom, nominal_steering(geom, mode)[None, :])
    twist = {Mode.LATERAL: [0.0, 1.0, 0.0], Mode.ROTATION: [0.0, 0.0, 1.0], Mode.STRAIGHT: [1.0, 0.0, 0.0]}[mode]
    return _column(geom, theta, np.array([twist]), np.zeros((1, 2))).T


@njit(cache=True, nogil=True, fastmath=False)
def car_like_model_into(l, b, a, r, alpha_v, H, dH):  # pragma: no cover - compiled
    """H_2 and dH_2/d alpha_v ``(9, 2)`` at one virtual angle, written into ``H`` and ``dH`` (eq. 8, 11).

    Column 0 (alpha_v_dot): steering at rest along the ICR relation; column 1 (x_ch_dot): v_x = 1,
    v_y = 0, omega = kappa = 2 tan(alpha_v) / l. The single implementation of H_2, shared by
    ``kinematic_model`` and the fused projection of ``agvdyn.dynamics``.
    """
    k = b / l
    s, c = np.sin(alpha_v), np.cos(alpha_v)
    s2, c2 = 2 * s * c, c * c - s * s
    # alpha_l = atan2(s, c - k s), alpha_r = atan2(s, c + k s); D = squared norm of those arguments
    D_l = 1 - k * s2 + k * k * s * s
    D_r = 1 + k * s2 + k * k * s * s
    root_l, root_r = np.sqrt(D_l), np.sqrt(D_r)
    cos_l, sin_l = (c - k * s) / root_l, s / root_l
    cos_r, sin_r = (c + k * s) / root_r, s / root_r
    d1_l, d1_r = 1 / D_l, 1 / D_r
    d2_l = (2 * k * c2 - k * k * s2) / (D_l * D_l)
    d2_r = (-2 * k * c2 - k * k * s2) / (D_r * D_r)
    kappa = 2 * s / (c * l)
    dkappa = 2 / (l * c * c)
    H[:, :] = 0.0
    dH[:, :] = 0.0
    H[3, 0], H[4, 0], dH[3, 0], dH[4, 0] = d1_l, d1_r, d2_l, d2_r
    H[0, 1], H[2, 1], dH[2, 1] = 1.0, kappa, dkappa
    for i in range(4):
        left = i < 2
        sigma = 1.0 if i % 2 == 0 else -1.0  # rear wheels mirrored: theta = sigma * alpha
        side = 1.0 if left else -1.0
        cx = l / 2 if i % 2 == 0 else -l / 2
        cy = b / 2 if left else -b / 2
        d1 = d1_l if left else d1_r
        d2 = d2_l if left else d2_r
        ct = cos_l if left else cos_r
        st = sigma * (sin_l if left else sin_r)
        vx, vy = 1 - kappa * cy, kappa * cx
        H[5 + i, 0] = -side * a * sigma * d1 / r
        dH[5 + i, 0] = -side * a * sigma * d2 / r
        H[5 + i, 1] = (ct * vx + st * vy - side * a * kappa) / r
        dH[5 + i, 1] = (sigma * d1 * (-st * vx + ct * vy) - ct * dkappa * cy + st * dkappa * cx - side * a * dkappa) / r


@njit(cache=True)
def _car_like_models(l, b, a, r, alpha_v):  # pragma: no cover - compiled
    n = alpha_v.shape[0]
    H = np.empty((n, 9, 2))
    dH = np.empty((n, 9, 2))
    for j in range(n):
        car_like_model_into(l, b, a, r, alpha_v[j], H[j], dH[j])
    return H, dH


def _car_like_model(geom: Geometry, alpha_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """H_2 ``(N, 9, 2)`` and dH_2/d alpha_v ``(N, 9, 2)`` at the virtual angles alpha_v."""
    return _car_like_models(geom.l, geom.b, geom.a, geom.r, np.ascontiguousarray(alpha_v, dtype=float))


def kinematic_model(geom: Geometry, mode, alpha, *, tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Kinematic model H_k(alpha) ``(N, 9, n_k)`` of motion mode k, eq. (4) and (10)-(13).

    Modes 3, 4 and straight use their nominal steering angles (eq. 9) and mode 2 the configuration
    on the ICR relation with the measured alpha_v, so that A(alpha) H_k(alpha) = 0 holds exactly;
    ``alpha`` must be in the mode within ``tolerance`` (ValueError otherwise).
    """
    mode = Mode.from_label(mode)
    alpha = as_alpha(alpha)
    check_mode(geom, mode, alpha, tolerance)
    if mode is Mode.CAR_LIKE:
        return _car_like_model(geom, _clip_virtual(geom, alpha))[0]
    return np.broadcast_to(_constant_model(geom, mode), (alpha.shape[0], N_Q, mode.dof))


def _clip_virtual(geom: Geometry, alpha: np.ndarray) -> np.ndarray:
    limit = max_virtual_angle(geom)
    return np.clip(virtual_from_steering(geom, alpha), -limit, limit)


def kinematic_model_dot(geom: Geometry, mode, alpha, alpha_dot, *, tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Time derivative dH_k/dt(alpha, alpha_dot) ``(N, 9, n_k)`` needed in eq. (20).

    Zero for the modes with constant H_k; in mode 2 ``dH_2/d alpha_v * alpha_v_dot`` with
    alpha_v_dot the least-squares fit of ``alpha_dot = f_ICR'(alpha_v) alpha_v_dot``.
    """
    mode = Mode.from_label(mode)
    alpha = as_alpha(alpha)
    n = alpha.shape[0]
    alpha_dot = _rows(alpha_dot, n, 2, "alpha_dot")
    check_mode(geom, mode, alpha, tolerance)
    if mode is not Mode.CAR_LIKE:
        return np.zeros((n, N_Q, mode.dof))
    av = _clip_virtual(geom, alpha)
    d1, _ = steering_from_virtual_derivatives(geom, av)
    av_dot = np.sum(d1 * alpha_dot, axis=1) / np.sum(d1 * d1, axis=1)
    return _car_like_model(geom, av)[1] * av_dot[:, None, None]


def joint_motion(geom: Geometry, mode, alpha, s_dot, s_ddot, *, tolerance: float = MODE_TOLERANCE):
    """Joint velocities and accelerations ``(q_dot, q_ddot)``, each ``(N, 9)``, eq. (4) and (20).

    ``q_dot = H_k s_dot``, ``q_ddot = dH_k/dt s_dot + H_k s_ddot``.
    """
    mode = Mode.from_label(mode)
    alpha = as_alpha(alpha)
    n = alpha.shape[0]
    s_dot = _rows(s_dot, n, mode.dof, "s_dot")
    s_ddot = _rows(s_ddot, n, mode.dof, "s_ddot")
    H = kinematic_model(geom, mode, alpha, tolerance=tolerance)
    q_dot = np.einsum("nij,nj->ni", H, s_dot)
    dH = kinematic_model_dot(geom, mode, alpha, q_dot[:, 3:5], tolerance=tolerance)
    q_ddot = np.einsum("nij,nj->ni", dH, s_dot) + np.einsum("nij,nj->ni", H, s_ddot)
    return q_dot, q_ddot


def admissible_basis(geom: Geometry, mode, alpha, *, tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Basis ``(N, 9, m)`` of all velocities admitted by the rolling constraints in mode k.

    Steering at rest (the columns of H_1) is always admissible; in modes 2, 3, 4 and straight the
    axle lines meet in one point (or are parallel) and one chassis motion is admissible too, so
    the null space of A(alpha) has dimension 3 while H_k spans only n_k of it.
    """
    mode = Mode.from_label(mode)
    alpha = as_alpha(alpha)
    n = alpha.shape[0]
    H1 = np.broadcast_to(_constant_model(geom, Mode.PARKING), (n, N_Q, 2))
    if mode is Mode.PARKING:
        return np.array(H1)
    H = kinematic_model(geom, mode, alpha, tolerance=tolerance)
    return np.concatenate([H1, H[:, :, -1:]], axis=2)
