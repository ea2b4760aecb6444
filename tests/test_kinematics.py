"""Kinematics: A H_k = 0, dH_k/dt, odometry, ICR relation, mode detection, bad input."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.kinematics import (
    Mode,
    admissible_basis,
    constraint_matrix,
    detect_mode,
    icr_residual,
    joint_motion,
    kinematic_model,
    kinematic_model_dot,
    max_virtual_angle,
    steering_from_virtual,
    steering_from_virtual_derivatives,
    virtual_from_steering,
)
from agvdyn.odometry import odometry
from agvdyn.platform import PROTOTYPE
from conftest import configurations, geometries, modes

seeds = st.integers(0, 2**32 - 1)


@settings(max_examples=60, deadline=None)
@given(geom=geometries, mode=modes, seed=seeds)
def test_constraints_annihilate_kinematic_model(geom, mode, seed):
    alpha = configurations(geom, mode, 16, np.random.default_rng(seed))
    A = constraint_matrix(geom, alpha)
    H = kinematic_model(geom, mode, alpha)
    assert H.shape == (16, 9, mode.dof)
    assert np.abs(A @ H).max() <= 1e-12 * max(1.0, np.abs(H).max())
    # and H_k has full column rank: the generalized velocities are independent
    assert (np.linalg.matrix_rank(H) == mode.dof).all()


@settings(max_examples=40, deadline=None)
@given(geom=geometries, mode=modes, seed=seeds)
def test_admissible_basis_is_the_null_space_of_A(geom, mode, seed):
    alpha = configurations(geom, mode, 8, np.random.default_rng(seed))
    A = constraint_matrix(geom, alpha)
    N = admissible_basis(geom, mode, alpha)
    assert np.abs(A @ N).max() < 1e-11
    null_dim = 9 - np.linalg.matrix_rank(A, tol=1e-9)
    assert (np.linalg.matrix_rank(N) == null_dim).all()
    # H_k lies in the admissible space
    H = kinematic_model(geom, mode, alpha)
    coef = np.linalg.lstsq(N[0], H[0], rcond=None)[0]
    assert np.allclose(N[0] @ coef, H[0], atol=1e-10)


def test_rank_of_A_per_mode():
    """rank 6 where the axle lines meet in one point (or are parallel), 7 in parking configurations."""
    rng = np.random.default_rng(1)
    for mode, rank in [(Mode.PARKING, 7), (Mode.CAR_LIKE, 6), (Mode.LATERAL, 6), (Mode.ROTATION, 6), (Mode.STRAIGHT, 6)]:
        A = constraint_matrix(PROTOTYPE, configurations(PROTOTYPE, mode, 20, rng))
        assert (np.linalg.matrix_rank(A, tol=1e-9) == rank).all(), mode


@settings(max_examples=40, deadline=None)
@given(geom=geometries, seed=seeds)
def test_kinematic_model_dot_matches_finite_differences(geom, seed):
    rng = np.random.default_rng(seed)
    limit = max_virtual_angle(geom)
    av = rng.uniform(-0.9, 0.9, 8) * limit
    av_dot = rng.normal(size=8)
    h = 1e-6
    H_plus = kinematic_model(geom, Mode.CAR_LIKE, steering_from_virtual(geom, av + h * av_dot))
    H_minus = kinematic_model(geom, Mode.CAR_LIKE, steering_from_virtual(geom, av - h * av_dot))
    alpha = steering_from_virtual(geom, av)
    alpha_dot = steering_from_virtual_derivatives(geom, av)[0] * av_dot[:, None]
    dH = kinematic_model_dot(geom, Mode.CAR_LIKE, alpha, alpha_dot)
    fd = (H_plus - H_minus) / (2 * h)
    assert np.allclose(dH, fd, rtol=1e-5, atol=1e-6 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("mode", [Mode.PARKING, Mode.LATERAL, Mode.ROTATION, Mode.STRAIGHT])
def test_constant_models_have_zero_derivative(mode):
    alpha = configurations(PROTOTYPE, mode, 5, np.random.default_rng(0))
    assert not kinematic_model_dot(PROTOTYPE, mode, alpha, np.ones((5, 2))).any()


@settings(max_examples=40, deadline=None)
@given(geom=geometries, seed=seeds)
def test_icr_derivatives_match_finite_differences(geom, seed):
    av = np.random.default_rng(seed).uniform(-0.9, 0.9, 10) * max_virtual_angle(geom)
    h = 1e-6
    d1, d2 = steering_from_virtual_derivatives(geom, av)
    fd1 = (steering_from_virtual(geom, av + h) - steering_from_virtual(geom, av - h)) / (2 * h)
    fd2 = (steering_from_virtual_derivatives(geom, av + h)[0] - steering_from_virtual_derivatives(geom, av - h)[0]) / (2 * h)
    assert np.allclose(d1, fd1, atol=1e-7)
    assert np.allclose(d2, fd2, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(geom=geometries, seed=seeds)
def test_icr_relation_eq_6_both_ways(geom, seed):
    av = np.random.default_rng(seed).uniform(-0.95, 0.95, 10) * max_virtual_angle(geom)
    av = av[np.abs(av) > 1e-3]
    alpha = steering_from_virtual(geom, av)
    y_icr = geom.l / (2 * np.tan(av))
    # eq. (6): l/(2 tan alpha_l) + b/2 = l/(2 tan alpha_r) - b/2 = l/(2 tan alpha_v)
    assert np.allclose(geom.l / (2 * np.tan(alpha[:, 0])) + geom.b / 2, y_icr, rtol=1e-9, atol=1e-9)
    assert np.allclose(geom.l / (2 * np.tan(alpha[:, 1])) - geom.b / 2, y_icr, rtol=1e-9, atol=1e-9)
    assert np.allclose(virtual_from_steering(geom, alpha), av, atol=1e-12)
    assert np.abs(icr_residual(geom, alpha)).max() < 1e-12


def test_icr_reference_value():
    alpha = steering_from_virtual(PROTOTYPE, [0.3])[0]
    # tan alpha_l = tan alpha_v / (1 - (b/l) tan alpha_v), tan alpha_r = tan alpha_v / (1 + (b/l) tan alpha_v)
    t = math.tan(0.3)
    assert alpha == pytest.approx([math.atan(t / (1 - t * 2 / 3)), math.atan(t / (1 + t * 2 / 3))])
    # the outer wheel reaches its stop at alpha_v = arctan(l/b)
    assert steering_from_virtual(PROTOTYPE, [max_virtual_angle(PROTOTYPE)])[0, 0] == pytest.approx(math.pi / 2)


@settings(max_examples=50, deadline=None)
@given(geom=geometries, mode=modes, seed=seeds)
def test_odometry_recovers_chassis_velocity(geom, mode, seed):
    rng = np.random.default_rng(seed)
    alpha = configurations(geom, mode, 12, rng)
    s_dot = rng.normal(size=(12, mode.dof))
    q_dot, _ = joint_motion(geom, mode, alpha, s_dot, np.zeros_like(s_dot))
    est = odometry(geom, alpha, q_dot[:, 3:5], q_dot[:, 5:])
    assert np.allclose(est, q_dot[:, :3], atol=1e-10)


def test_odometry_least_squares_with_inconsistent_wheels():
    """One slipping wheel: odometry is the least-squares fit, not any single wheel's answer."""
    alpha = np.zeros((1, 2))
    beta_dot = np.array([[10.0, 10.0, 10.0, 10.4]])
    v = odometry(PROTOTYPE, alpha, np.zeros((1, 2)), beta_dot)
    assert 1.0 < v[0, 0] < 1.04 * 1.0 + 1e-9


@pytest.mark.parametrize("mode", list(Mode))
def test_detect_mode_on_exact_configurations(mode):
    alpha = configurations(PROTOTYPE, mode, 50, np.random.default_rng(3))
    detected = detect_mode(PROTOTYPE, alpha)
    if mode is Mode.CAR_LIKE:
        # a random car-like configuration may come close to straight motion
        assert set(detected) <= {Mode.CAR_LIKE, Mode.STRAIGHT}
        assert (detected == Mode.CAR_LIKE).mean() > 0.9
    else:
        assert (detected == mode).all()


def test_detect_mode_tolerance():
    rot = PROTOTYPE.rotation_angle
    alpha = np.array([[-rot + 0.015, rot], [-rot + 0.03, rot], [0.01, -0.01], [0.5, 0.1]])
    assert detect_mode(PROTOTYPE, alpha).tolist() == [Mode.ROTATION, Mode.PARKING, Mode.STRAIGHT, Mode.PARKING]
    assert detect_mode(PROTOTYPE, alpha, tolerance=0.05)[1] == Mode.ROTATION


@pytest.mark.parametrize(
    "alpha, message",
    [
        (np.array([[1.7, 0.0]]), "alpha_l"),
        (np.array([[0.0, np.nan]]), "finite"),
        (np.array([[0.0, -1.6]]), "mechanical stops"),
    ],
)
def test_bad_angles_are_refused(alpha, message):
    with pytest.raises(ValueError, match=message):
        constraint_matrix(PROTOTYPE, alpha)


def test_configuration_not_in_mode_is_refused():
    with pytest.raises(ValueError, match=r"alpha\[1\].*not in mode 4"):
        kinematic_model(PROTOTYPE, Mode.ROTATION, np.array([[-PROTOTYPE.rotation_angle, PROTOTYPE.rotation_angle], [0.2, 0.2]]))
    with pytest.raises(ValueError, match="ICR relation"):
        kinematic_model(PROTOTYPE, Mode.CAR_LIKE, np.array([[0.3, -0.2]]))
    with pytest.raises(ValueError, match="alpha_v"):
        steering_from_virtual(PROTOTYPE, [1.2])
    with pytest.raises(ValueError, match="unknown motion mode"):
        Mode.from_label("6")


def test_odometry_equals_pseudoinverse_of_eq_3_on_inconsistent_rates():
    """Random (slipping) rates: the compiled solve equals -A_ch^+ (A_alpha alpha_dot + A_beta beta_dot)."""
    rng = np.random.default_rng(7)
    alpha, alpha_dot, beta_dot = rng.uniform(-1.5, 1.5, (50, 2)), rng.normal(size=(50, 2)), rng.normal(size=(50, 4))
    A = constraint_matrix(PROTOTYPE, alpha)
    rhs = np.einsum("nij,nj->ni", A[:, :, 3:5], alpha_dot) + np.einsum("nij,nj->ni", A[:, :, 5:], beta_dot)
    expected = -np.einsum("nij,nj->ni", np.linalg.pinv(A[:, :, :3]), rhs)
    assert np.allclose(odometry(PROTOTYPE, alpha, alpha_dot, beta_dot), expected, atol=1e-12)
