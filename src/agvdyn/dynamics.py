"""Parameter-linear dynamics: regressor Theta (eq. 16), input B u (eq. 17), projection (eq. 19)
and the feed-forward law (eq. 21).

``Theta(q, q_dot, q_ddot) p = B u + A^T lambda`` with p in the order of eq. (18)
``(C_l, d_vl, d_cl, C_r, d_vr, d_cr, m_ch, C_ch, d_vw, d_cw, B_w)``; the rows are the nine
coordinates ``(x_ch, y_ch, gamma_ch, alpha_l, alpha_r, beta_fl, beta_rl, beta_fr, beta_rr)``.
"""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit
from agvdyn.kinematics import (
    MODE_TOLERANCE,
    N_Q,
    Mode,
    admissible_basis,
    as_alpha,
    car_like_model_into,
    check_mode,
    icr_state,
    joint_motion,
    kinematic_model,
    max_virtual_angle,
)
from agvdyn.kinematics.constraints import _rows
from agvdyn._numba_cache import drop_stale_cache
from agvdyn.kinematics import constraints, models
from agvdyn.dynamics_extended import extension_forces
from agvdyn.model_spec import ModelParameters
from agvdyn.platform import EPSILON, PARAMETER_NAMES, Geometry, Parameters

drop_stale_cache(__file__, constraints.__file__, models.__file__)  # compiled callees in those files

N_P = len(PARAMETER_NAMES)
_I = {name: i for i, name in enumerate(PARAMETER_NAMES)}


def _motion(q_dot, q_ddot) -> tuple[np.ndarray, np.ndarray]:
    q_dot = np.atleast_2d(np.asarray(q_dot, dtype=float))
    n = q_dot.shape[0]
    return _rows(q_dot, n, N_Q, "q_dot"), _rows(q_ddot, n, N_Q, "q_ddot")


def regressor(q_dot, q_ddot, epsilon: float = EPSILON) -> np.ndarray:
    """Regressor Theta(q, q_dot, q_ddot) ``(N, 9, 11)`` of eq. (16), Coulomb friction d_c tanh(v/epsilon).

    Example: a chassis accelerating at 1 m/s^2 has ``Theta[:, 0, m_ch] = 1``.
    """
    qd, qdd = _motion(q_dot, q_ddot)
    n = qd.shape[0]
    T = np.zeros((n, N_Q, N_P))
    vx, vy, w = qd[:, 0], qd[:, 1], qd[:, 2]
    T[:, 0, _I["m_ch"]] = qdd[:, 0] - vy * w
    T[:, 1, _I["m_ch"]] = qdd[:, 1] + vx * w
    T[:, 2, _I["C_ch"]] = T[:, 2, _I["C_l"]] = T[:, 2, _I["C_r"]] = qdd[:, 2]
    for row, (C, dv, dc) in ((3, ("C_l", "d_vl", "d_cl")), (4, ("C_r", "d_vr", "d_cr"))):
        T[:, row, _I[C]] = qdd[:, row]
        T[:, row, _I[dv]] = qd[:, row]
        T[:, row, _I[dc]] = np.tanh(qd[:, row] / epsilon)
    T[:, 5:, _I["B_w"]] = qdd[:, 5:]
    T[:, 5:, _I["d_vw"]] = qd[:, 5:]
    T[:, 5:, _I["d_cw"]] = np.tanh(qd[:, 5:] / epsilon)
    return T


#: The distinct nonzero entries of Theta (eq. 16), the columns of :func:`regressor_signals`.
REGRESSOR_SIGNALS = (
    "a_x", "a_y", "gamma_ddot",
    "alpha_l_ddot", "alpha_l_dot", "tanh_alpha_l", "alpha_r_ddot", "alpha_r_dot", "tanh_alpha_r",
    *(f"beta_{w}_ddot" for w in ("fl", "rl", "fr", "rr")),
    *(f"beta_{w}_dot" for w in ("fl", "rl", "fr", "rr")),
    *(f"tanh_beta_{w}" for w in ("fl", "rl", "fr", "rr")),
)


def regressor_signals(q_dot, q_ddot, epsilon: float = EPSILON) -> np.ndarray:
    """The 21 distinct nonzero entries of Theta (eq. 16) ``(N, 21)``, in :data:`REGRESSOR_SIGNALS` order.

    ``a_x = x_ddot - y_dot gamma_dot``, ``a_y = y_ddot + x_dot gamma_dot``, ``gamma_ddot``, then per
    steering side acceleration, rate and ``tanh(rate / epsilon)``, then the wheels' accelerations,
    rates and tanh terms. Theta is linear in these, so a linear filter applied to them is the
    filter applied to Theta (parallel filtering); :func:`project_signals` builds ``H_k^T Theta``.
    """
    qd, qdd = _motion(q_dot, q_ddot)
    out = np.empty((qd.shape[0], len(REGRESSOR_SIGNALS)))
    out[:, 0] = qdd[:, 0] - qd[:, 1] * qd[:, 2]
    out[:, 1] = qdd[:, 1] + qd[:, 0] * qd[:, 2]
    out[:, 2] = qdd[:, 2]
    for k, row in enumerate((3, 4)):
        out[:, 3 + 3 * k] = qdd[:, row]
        out[:, 4 + 3 * k] = qd[:, row]
        out[:, 5 + 3 * k] = np.tanh(qd[:, row] / epsilon)
    out[:, 9:13] = qdd[:, 5:]
    out[:, 13:17] = qd[:, 5:]
    out[:, 17:21] = np.tanh(qd[:, 5:] / epsilon)
    return out


def project_signals(H: np.ndarray, signals: np.ndarray) -> np.ndarray:
    """``H_k^T Theta`` ``(N, n_k, 11)`` of eq. (19) from the signals of :func:`regressor_signals`.

    ``H`` is ``(N, 9, n_k)`` or ``(1, 9, n_k)`` (a constant model). Equal to
    :func:`projected_regressor` for the same motion; used where Theta's entries were filtered.
    """
    S = signals[:, :, None]
    W = H[:, 5:, :]
    out = np.empty((signals.shape[0], H.shape[2], N_P))
    rot = H[:, 2, :] * S[:, 2]
    out[:, :, _I["m_ch"]] = H[:, 0, :] * S[:, 0] + H[:, 1, :] * S[:, 1]
    out[:, :, _I["C_ch"]] = rot
    out[:, :, _I["C_l"]] = rot + H[:, 3, :] * S[:, 3]
    out[:, :, _I["d_vl"]] = H[:, 3, :] * S[:, 4]
    out[:, :, _I["d_cl"]] = H[:, 3, :] * S[:, 5]
    out[:, :, _I["C_r"]] = rot + H[:, 4, :] * S[:, 6]
    out[:, :, _I["d_vr"]] = H[:, 4, :] * S[:, 7]
    out[:, :, _I["d_cr"]] = H[:, 4, :] * S[:, 8]
    out[:, :, _I["B_w"]] = np.einsum("nwk,nw->nk", W, signals[:, 9:13]) if W.shape[0] > 1 else signals[:, 9:13] @ W[0]
    out[:, :, _I["d_vw"]] = np.einsum("nwk,nw->nk", W, signals[:, 13:17]) if W.shape[0] > 1 else signals[:, 13:17] @ W[0]
    out[:, :, _I["d_cw"]] = np.einsum("nwk,nw->nk", W, signals[:, 17:21]) if W.shape[0] > 1 else signals[:, 17:21] @ W[0]
    return out


def input_matrix(geom: Geometry) -> np.ndarray:
    """Input matrix B ``(9, 4)`` of eq. (17): wheel torque = i_G M_mot on each wheel coordinate."""
    B = np.zeros((N_Q, 4))
    B[5:, :] = geom.i_G * np.eye(4)
    return B


def projected_regressor(geom: Geometry, mode, alpha, q_dot, q_ddot, *, epsilon: float = EPSILON,
                        tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Projected regressor H_k^T Theta ``(N, n_k, 11)``: left-hand side of eq. (19).

    Computed sample by sample in compiled code from the sparsity of Theta (eq. 16) without forming
    it; in mode 2, H_2 is evaluated in the same pass (the hot path of identification).
    """
    mode = Mode.from_label(mode)
    alpha = as_alpha(alpha)
    n = alpha.shape[0]
    qd, qdd = (np.ascontiguousarray(x) for x in _motion(q_dot, q_ddot))
    if qd.shape[0] != n:
        raise ValueError(f"q_dot has {qd.shape[0]} rows, alpha {n}: expected the same number of samples")
    out = np.empty((n, mode.dof, N_P))
    if mode is Mode.CAR_LIKE:
        bad = _project_car_like(geom.l, geom.b, geom.a, geom.r, max_virtual_angle(geom), alpha, qd, qdd,
                                epsilon, tolerance, out)
        if bad >= 0:
            check_mode(geom, mode, alpha[bad : bad + 1], tolerance)  # raises with the offending values
        return out
    H = kinematic_model(geom, mode, alpha[:1], tolerance=tolerance)[0]
    check_mode(geom, mode, alpha, tolerance)
    _project_constant(np.ascontiguousarray(H), qd, qdd, epsilon, out)
    return out


@njit(cache=True)
def _project_into(H, qd, qdd, tanh_a, tanh_w, out):  # pragma: no cover - compiled
    """One sample of H^T Theta ``(k, 11)`` from the nonzero entries of Theta, eq. (16) and (19)."""
    for c in range(H.shape[1]):
        rot = H[2, c] * qdd[2]
        out[c, 7] = rot  # C_ch
        out[c, 6] = H[0, c] * (qdd[0] - qd[1] * qd[2]) + H[1, c] * (qdd[1] + qd[0] * qd[2])  # m_ch
        out[c, 0] = rot + H[3, c] * qdd[3]  # C_l
        out[c, 1] = H[3, c] * qd[3]
        out[c, 2] = H[3, c] * tanh_a[0]
        out[c, 3] = rot + H[4, c] * qdd[4]  # C_r
        out[c, 4] = H[4, c] * qd[4]
        out[c, 5] = H[4, c] * tanh_a[1]
        dv = dc = bw = 0.0
        for i in range(4):
            h = H[5 + i, c]
            dv += h * qd[5 + i]
            dc += h * tanh_w[i]
            bw += h * qdd[5 + i]
        out[c, 8], out[c, 9], out[c, 10] = dv, dc, bw


@njit(cache=True)
def _tanh_terms(qd, epsilon, tanh_a, tanh_w):  # pragma: no cover - compiled
    tanh_a[0] = np.tanh(qd[3] / epsilon)
    tanh_a[1] = np.tanh(qd[4] / epsilon)
    for i in range(4):
        tanh_w[i] = np.tanh(qd[5 + i] / epsilon)


@njit(cache=True)
def _project_constant(H, qd, qdd, epsilon, out):  # pragma: no cover - compiled
    tanh_a, tanh_w = np.empty(2), np.empty(4)
    for j in range(qd.shape[0]):
        _tanh_terms(qd[j], epsilon, tanh_a, tanh_w)
        _project_into(H, qd[j], qdd[j], tanh_a, tanh_w, out[j])


@njit(cache=True)
def _project_car_like(l, b, a, r, limit, alpha, qd, qdd, epsilon, tolerance, out):  # pragma: no cover - compiled
    """H_2^T Theta for every sample; returns the first row off the ICR relation, or -1."""
    k = b / l
    H, dH = np.empty((9, 2)), np.empty((9, 2))
    tanh_a, tanh_w = np.empty(2), np.empty(4)
    bad = -1
    for j in range(alpha.shape[0]):
        av, residual = icr_state(k, alpha[j, 0], alpha[j, 1])
        if bad < 0 and (abs(residual) > tolerance or abs(av) > limit + tolerance):
            bad = j
        av = min(max(av, -limit), limit)
        car_like_model_into(l, b, a, r, av, H, dH)
        _tanh_terms(qd[j], epsilon, tanh_a, tanh_w)
        _project_into(H, qd[j], qdd[j], tanh_a, tanh_w, out[j])
    return bad


def projected_input(geom: Geometry, mode, alpha, u, *, tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Generalized torques H_k^T B u ``(N, n_k)`` of the motor torques u ``(N, 4)``: right-hand side of eq. (19)."""
    H = kinematic_model(geom, mode, alpha, tolerance=tolerance)
    u = _rows(u, H.shape[0], 4, "u")
    return geom.i_G * np.einsum("nik,ni->nk", H[:, 5:, :], u)


def generalized_forces(q_dot, q_ddot, params: Parameters | ModelParameters, epsilon: float = EPSILON) -> np.ndarray:
    """Model forces Theta(q, q_dot, q_ddot) p ``(N, 9)`` of eq. (15)-(16), from the nonzero entries
    of Theta (:func:`regressor`) without forming it; those of :func:`generalized_forces_model` when
    ``params`` is a :class:`~agvdyn.model_spec.ModelParameters`."""
    if isinstance(params, ModelParameters):
        return generalized_forces_model(q_dot, q_ddot, params, epsilon)
    qd, qdd = _motion(q_dot, q_ddot)
    p = params.to_vector()
    f = np.empty((qd.shape[0], N_Q))
    f[:, 0] = (qdd[:, 0] - qd[:, 1] * qd[:, 2]) * p[_I["m_ch"]]
    f[:, 1] = (qdd[:, 1] + qd[:, 0] * qd[:, 2]) * p[_I["m_ch"]]
    f[:, 2] = qdd[:, 2] * (p[_I["C_l"]] + p[_I["C_r"]] + p[_I["C_ch"]])
    for row, (C, dv, dc) in ((3, ("C_l", "d_vl", "d_cl")), (4, ("C_r", "d_vr", "d_cr"))):
        f[:, row] = qdd[:, row] * p[_I[C]] + qd[:, row] * p[_I[dv]] + np.tanh(qd[:, row] / epsilon) * p[_I[dc]]
    f[:, 5:] = qdd[:, 5:] * p[_I["B_w"]] + qd[:, 5:] * p[_I["d_vw"]] + np.tanh(qd[:, 5:] / epsilon) * p[_I["d_cw"]]
    return f


def generalized_forces_model(q_dot, q_ddot, model: ModelParameters, epsilon: float = EPSILON) -> np.ndarray:
    """Forces Theta p ``(N, 9)`` of a possibly extended model (:mod:`agvdyn.model_spec`): eq. (15)-(16)
    with the Stribeck friction per joint group and the off-centre chassis rows when the model has them
    (:func:`agvdyn.dynamics_extended.extension_forces`); the paper's :func:`generalized_forces` of
    ``model.parameters``, bit for bit, when it has neither. The delay does not enter the forces."""
    f = generalized_forces(q_dot, q_ddot, model.parameters, epsilon)
    if model.spec.stribeck or model.spec.com_offset:
        f += extension_forces(q_dot, q_ddot, model, epsilon)
    return f


def feedforward_torques(geom: Geometry, params: Parameters | ModelParameters, mode, alpha, s_dot, s_ddot, *,
                        epsilon: float = EPSILON, tolerance: float = MODE_TOLERANCE,
                        motion: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Motor torques u ``(N, 4)`` of the feed-forward law, eq. (21), for a desired motion in mode k.

    ``q_dot, q_ddot`` follow from eq. (4) and (20). The paper distributes ``H_k^T Theta p`` with a
    right inverse of ``H_k^T B``. Where the axle lines meet in one point (modes 2, 4, straight) the
    admissible velocities form a 3-dimensional space N (steering either side at rest plus the
    chassis motion), one direction more than H_k spans; a right inverse of H_k^T B alone may push
    on that direction and let the passive steering drift. Here u is the minimum-norm solution of
    ``N^T B u = N^T Theta p``: the net generalized force on every admissible direction is zero, the
    mode's generalized torques are the model's, and the extra direction gets exactly what holds the
    steering on the trajectory.

    In mode 3 the steering sits at its stops and the wheel torque patterns of the lateral motion
    and of steering at rest are linearly dependent (``h_y = (h_l + h_r)/a`` on the wheels): the
    steering force that the lateral force implies is put on the side whose stop absorbs it (each
    steering is pressed into its stop, never pulled off).

    ``motion``: ``(q_dot, q_ddot)`` of the same motion when already computed (eq. 4 and 20).

    ``params`` a :class:`~agvdyn.model_spec.ModelParameters`: the forces of the extended model
    (:func:`generalized_forces_model`), distributed the same way. Its torque delay ``delay_s`` does
    not change the torques, only when the logged column shows them: the torque logged at t acted at
    ``t - delay_s``. Where the logged column is the drive's command, the torque that must act at t is
    therefore to be commanded at ``t + delay_s`` (a command column leads the motion: ``delay_s < 0``,
    command ``-delay_s`` early); a positive ``delay_s`` is a lag of the measurement, not of the drive.
    """
    mode = Mode.from_label(mode)
    alpha = as_alpha(alpha)
    if motion is None:
        q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot, tolerance=tolerance)
    else:
        check_mode(geom, mode, alpha, tolerance)
        q_dot, q_ddot = motion
    f = generalized_forces(q_dot, q_ddot, params, epsilon)
    if mode is not Mode.CAR_LIKE:
        return _constant_basis_torques(geom, mode, admissible_basis(geom, mode, alpha[:1], tolerance=tolerance)[0], f)
    N = admissible_basis(geom, mode, alpha, tolerance=tolerance)
    M = geom.i_G * np.swapaxes(N[:, 5:, :], 1, 2)  # N^T B  (n, m, 4)
    g = np.einsum("nim,ni->nm", N, f)
    if mode is Mode.LATERAL:  # N^T B has rank 2: consistent targets, least-squares right inverse
        g = _lateral_steering_targets(geom, g)
        return np.einsum("nij,nj->ni", np.linalg.pinv(M, rcond=1e-10), g)
    # full row rank: minimum-norm solution u = M^T (M M^T)^-1 g
    y = np.linalg.solve(np.einsum("nik,njk->nij", M, M), g[..., None])[..., 0]
    return np.einsum("nik,ni->nk", M, y)


def _constant_basis_torques(geom: Geometry, mode: Mode, N: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Motor torques ``(n, 4)`` of :func:`feedforward_torques` where the admissible basis N ``(9, m)``
    does not depend on alpha (modes 1, 3, 4, straight): N^T B and its right inverse are formed once."""
    M = geom.i_G * N[5:, :].T  # N^T B  (m, 4)
    g = f @ N
    if mode is Mode.LATERAL:
        return _lateral_steering_targets(geom, g) @ np.linalg.pinv(M, rcond=1e-10).T
    return np.linalg.solve(M @ M.T, g.T).T @ M


def _lateral_steering_targets(geom: Geometry, g: np.ndarray) -> np.ndarray:
    """Mode 3: steering targets (T_l, T_r) consistent with T_l + T_r = a F_y, pressing into the stops.

    The left stop is at -pi/2 (net steering force must be <= 0), the right one at +pi/2 (>= 0).
    """
    g = g.copy()
    excess = geom.a * g[:, 2] - (g[:, 0] + g[:, 1])
    g[:, 1] += np.where(excess >= 0, excess, 0.0)
    g[:, 0] += np.where(excess < 0, excess, 0.0)
    return g
