"""Dynamics: regressor against an independent Lagrange computation, eq. (19), feed-forward, power."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.dynamics import (
    feedforward_torques,
    generalized_forces,
    input_matrix,
    projected_input,
    projected_regressor,
    regressor,
)
from agvdyn.kinematics import Mode, admissible_basis, constraint_matrix, joint_motion, kinematic_model
from agvdyn.platform import EPSILON, PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Parameters
from conftest import configurations, geometries, modes

seeds = st.integers(0, 2**32 - 1)
positive_parameters = st.builds(
    Parameters, *[st.floats(0.05, 900.0) for _ in PARAMETER_NAMES]
)


def lagrange_forces(q_dot, q_ddot, p: Parameters) -> np.ndarray:
    """Independent inverse dynamics: Lagrange equations of the model of sec. 4 in an inertial frame.

    Kinetic energy T = m/2 |v_inertial|^2 + (C_ch + C_l + C_r)/2 omega^2 + C_l/2 alpha_l_dot^2 + ...,
    written with the world-frame velocity rotated into the body frame; the generalized forces along
    the body-frame quasi-velocities follow from d/dt(m v_world) rotated back.
    """
    n = q_dot.shape[0]
    out = np.zeros((n, 9))
    vx, vy, w = q_dot[:, 0], q_dot[:, 1], q_dot[:, 2]
    ax, ay, dw = q_ddot[:, 0], q_ddot[:, 1], q_ddot[:, 2]
    # world acceleration of the chassis expressed in the body frame: v_dot + omega x v
    out[:, 0] = p.m_ch * (ax - w * vy)
    out[:, 1] = p.m_ch * (ay + w * vx)
    out[:, 2] = (p.C_ch + p.C_l + p.C_r) * dw
    coulomb = lambda v: np.tanh(v / EPSILON)  # noqa: E731
    out[:, 3] = p.C_l * q_ddot[:, 3] + p.d_vl * q_dot[:, 3] + p.d_cl * coulomb(q_dot[:, 3])
    out[:, 4] = p.C_r * q_ddot[:, 4] + p.d_vr * q_dot[:, 4] + p.d_cr * coulomb(q_dot[:, 4])
    out[:, 5:] = p.B_w * q_ddot[:, 5:] + p.d_vw * q_dot[:, 5:] + p.d_cw * coulomb(q_dot[:, 5:])
    return out


@settings(max_examples=50, deadline=None)
@given(p=positive_parameters, seed=seeds)
def test_regressor_times_parameters_matches_independent_dynamics(p, seed):
    rng = np.random.default_rng(seed)
    q_dot, q_ddot = rng.normal(size=(2, 30, 9))
    assert np.allclose(regressor(q_dot, q_ddot) @ p.to_vector(), lagrange_forces(q_dot, q_ddot, p), rtol=1e-12, atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(geom=geometries, mode=modes, seed=seeds)
def test_projected_regressor_equals_H_transpose_Theta(geom, mode, seed):
    rng = np.random.default_rng(seed)
    alpha = configurations(geom, mode, 10, rng)
    q_dot, q_ddot = joint_motion(geom, mode, alpha, rng.normal(size=(10, mode.dof)), rng.normal(size=(10, mode.dof)))
    H = kinematic_model(geom, mode, alpha)
    expected = np.einsum("nik,nij->nkj", H, regressor(q_dot, q_ddot))
    assert np.allclose(projected_regressor(geom, mode, alpha, q_dot, q_ddot), expected, rtol=1e-12, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(geom=geometries, mode=modes, p=positive_parameters, seed=seeds)
def test_feedforward_reproduces_eq_19_and_holds_the_extra_direction(geom, mode, p, seed):
    rng = np.random.default_rng(seed)
    alpha = configurations(geom, mode, 10, rng)
    s_dot, s_ddot = rng.normal(size=(2, 10, mode.dof))
    u = feedforward_torques(geom, p, mode, alpha, s_dot, s_ddot)
    q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
    lhs = projected_regressor(geom, mode, alpha, q_dot, q_ddot) @ p.to_vector()
    scale = max(1.0, np.abs(lhs).max())
    assert np.allclose(projected_input(geom, mode, alpha, u), lhs, atol=1e-9 * scale)
    # net generalized force B u - Theta p on the whole admissible space (null space of A)
    net = np.einsum("nim,ni->nm", admissible_basis(geom, mode, alpha), u @ input_matrix(geom).T - generalized_forces(q_dot, q_ddot, p))
    if mode is Mode.LATERAL:
        # steering at the stops: pressed into them (left stop at -pi/2, right at +pi/2), never pulled off
        assert (net[:, 0] <= 1e-9 * scale).all() and (net[:, 1] >= -1e-9 * scale).all()
        assert np.allclose(net[:, 2], 0, atol=1e-9 * scale)
    else:
        assert np.allclose(net, 0, atol=1e-9 * scale)


def test_plain_pseudoinverse_would_push_the_unused_direction():
    """The reason for the distribution: pinv(H_2^T B) alone puts force on the differential steering.

    (Without steering motion the front/rear symmetry of mode 2 hides it; steering friction differs per side.)
    """
    geom, p = PROTOTYPE, PAPER_PARAMETERS
    alpha = configurations(geom, Mode.CAR_LIKE, 50, np.random.default_rng(5))
    s_dot = np.column_stack([np.full(50, 0.3), np.ones(50)])
    s_ddot = np.column_stack([np.zeros(50), np.full(50, 0.5)])
    q_dot, q_ddot = joint_motion(geom, Mode.CAR_LIKE, alpha, s_dot, s_ddot)
    H = kinematic_model(geom, Mode.CAR_LIKE, alpha)
    tau = np.einsum("nik,ni->nk", H, generalized_forces(q_dot, q_ddot, p))
    HB = np.einsum("nik,ij->nkj", H, input_matrix(geom))
    u_naive = np.einsum("njk,nk->nj", np.linalg.pinv(HB), tau)
    N = admissible_basis(geom, Mode.CAR_LIKE, alpha)
    f = generalized_forces(q_dot, q_ddot, p)
    net_naive = np.einsum("nim,ni->nm", N, u_naive @ input_matrix(geom).T - f)
    u = feedforward_torques(geom, p, Mode.CAR_LIKE, alpha, s_dot, s_ddot)
    net = np.einsum("nim,ni->nm", N, u @ input_matrix(geom).T - f)
    assert np.abs(net_naive[:, :2]).max() > 1.0  # N m of steering torque that makes the steering drift
    assert np.abs(net).max() < 1e-8


def test_straight_motion_torques_by_hand():
    """Straight acceleration: each motor carries a quarter of (m_ch r + 4 B_w / r) a / i_G plus friction."""
    geom, p = PROTOTYPE, PAPER_PARAMETERS
    v, acc = 0.5, 0.4
    u = feedforward_torques(geom, p, Mode.STRAIGHT, np.zeros((1, 2)), [[v]], [[acc]])
    wheel_rate = v / geom.r
    per_wheel = (p.m_ch * acc * geom.r / 4 + p.B_w * acc / geom.r + p.d_vw * wheel_rate
                 + p.d_cw * np.tanh(wheel_rate / EPSILON))
    assert u == pytest.approx(np.full((1, 4), per_wheel / geom.i_G), rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(mode=modes, seed=seeds)
def test_power_balance_of_feedforward(mode, seed):
    """Motor power = rate of kinetic energy + dissipated power (constraint forces do no work)."""
    geom, p = PROTOTYPE, PAPER_PARAMETERS
    rng = np.random.default_rng(seed)
    alpha = configurations(geom, mode, 10, rng)
    s_dot, s_ddot = rng.normal(size=(2, 10, mode.dof))
    u = feedforward_torques(geom, p, mode, alpha, s_dot, s_ddot)
    q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
    motor_power = np.sum(geom.i_G * u * q_dot[:, 5:], axis=1)
    inertia = np.array([p.m_ch, p.m_ch, p.C_ch + p.C_l + p.C_r, p.C_l, p.C_r] + [p.B_w] * 4)
    kinetic_rate = np.sum(inertia * q_dot * q_ddot, axis=1)  # m (v . v_dot); omega x v does no work
    d_v = np.array([0, 0, 0, p.d_vl, p.d_vr] + [p.d_vw] * 4)
    d_c = np.array([0, 0, 0, p.d_cl, p.d_cr] + [p.d_cw] * 4)
    dissipated = np.sum(d_v * q_dot**2 + d_c * q_dot * np.tanh(q_dot / EPSILON), axis=1)
    steering_stop_power = 0.0  # in mode 3 the stops do no work: alpha_dot = 0
    assert np.allclose(motor_power, kinetic_rate + dissipated + steering_stop_power, rtol=1e-9, atol=1e-8)


def test_constraint_forces_vanish_under_projection():
    """H_k^T A^T lambda = 0 for any lambda (eq. 5 and 19)."""
    rng = np.random.default_rng(2)
    for mode in Mode:
        alpha = configurations(PROTOTYPE, mode, 5, rng)
        lam = rng.normal(size=(5, 8))
        H = kinematic_model(PROTOTYPE, mode, alpha)
        generalized = np.einsum("nik,nji,nj->nk", H, constraint_matrix(PROTOTYPE, alpha), lam)
        assert np.abs(generalized).max() < 1e-12


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="q_ddot"):
        regressor(np.zeros((3, 9)), np.zeros((3, 8)))
    with pytest.raises(ValueError, match="s_dot"):
        feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, Mode.CAR_LIKE, np.zeros((2, 2)), np.zeros((2, 1)), np.zeros((2, 2)))


@pytest.mark.parametrize("mode", [Mode.CAR_LIKE, Mode.STRAIGHT, Mode.ROTATION])
def test_parking_feedforward_does_not_push_the_chassis_where_it_could_move(mode):
    """Steering at rest through a configuration where the axle lines meet (mode 1 passing a mode-2/4
    configuration): front and rear wheels of a side roll alike in the chassis motion and opposite
    in steering, so the minimum-norm steering torques put no force on the chassis direction."""
    geom, p = PROTOTYPE, PAPER_PARAMETERS
    rng = np.random.default_rng(11)
    alpha = configurations(geom, mode, 20, rng)
    u = feedforward_torques(geom, p, Mode.PARKING, alpha, rng.normal(size=(20, 2)), rng.normal(size=(20, 2)))
    chassis = admissible_basis(geom, mode, alpha)[:, :, -1]
    assert np.abs(np.einsum("ni,ni->n", chassis, u @ input_matrix(geom).T)).max() < 1e-9


def test_parking_feedforward_at_the_lateral_stops_pushes_sideways():
    """The exception: at alpha = (-pi/2, pi/2) the wheel patterns coincide (h_y = (h_l + h_r)/a),
    so steering at the stops is a sideways force on the chassis (why mode 3 is entered at rest)."""
    geom, p = PROTOTYPE, PAPER_PARAMETERS
    alpha = configurations(geom, Mode.LATERAL, 5, np.random.default_rng(2))
    u = feedforward_torques(geom, p, Mode.PARKING, alpha, np.ones((5, 2)), np.ones((5, 2)))
    lateral = admissible_basis(geom, Mode.LATERAL, alpha)[:, :, -1]
    assert np.abs(np.einsum("ni,ni->n", lateral, u @ input_matrix(geom).T)).min() > 1.0
