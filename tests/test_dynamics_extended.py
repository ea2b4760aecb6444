"""The model beyond the paper in the inverse dynamics (issue 30): the off-centre chassis against an
independent Lagrange computation, the Stribeck law against the paper's, feed-forward invariants."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.dynamics import (
    feedforward_torques,
    generalized_forces,
    generalized_forces_model,
    input_matrix,
    projected_input,
)
from agvdyn.dynamics_extended import breakaway_forces, com_offset_forces, extension_forces
from agvdyn.kinematics import Mode, admissible_basis, joint_motion, kinematic_model
from agvdyn.model_spec import ModelParameters, ModelSpec, joint_friction
from agvdyn.platform import EPSILON, PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Parameters
from conftest import configurations, geometries, modes

seeds = st.integers(0, 2**32 - 1)
positive_parameters = st.builds(Parameters, *[st.floats(0.05, 900.0) for _ in PARAMETER_NAMES])
STRIBECK = ModelSpec(friction="stribeck")
OFFSET = ModelSpec(com_offset=True)
BOTH = ModelSpec(friction="stribeck", com_offset=True)


@st.composite
def extended_models(draw, spec: ModelSpec = BOTH, base=positive_parameters) -> ModelParameters:
    """A model with random breakaway levels (0..3 d_c), Stribeck velocities and centre of mass."""
    p = draw(base)
    extra = {}
    if spec.stribeck:
        for g, d_c in (("l", p.d_cl), ("r", p.d_cr), ("w", p.d_cw)):
            extra[f"d_s{g}"] = d_c * draw(st.floats(0.0, 3.0))
            extra[f"w_s{g}"] = draw(st.floats(0.005, 0.5))
    if spec.com_offset:
        extra["x_c"], extra["y_c"] = draw(st.floats(-0.5, 0.5)), draw(st.floats(-0.5, 0.5))
    return ModelParameters(p, extra, spec=spec)


# --- the independent reference: Lagrange's equations in world coordinates ------------------------

def _rotation(gamma: float) -> np.ndarray:
    c, s = math.cos(gamma), math.sin(gamma)
    return np.array([[c, -s], [s, c]])


def _kinetic_energy(q: np.ndarray, q_dot: np.ndarray, model: ModelParameters) -> float:
    """T of the vehicle in world coordinates (X, Y, gamma, alpha_l, alpha_r, beta_*): the chassis mass
    at its centre of mass r_c = (x_c, y_c) (chassis frame), yaw inertia C_ch - m |r_c|^2 about it
    (C_ch is about the reference point), the steering bodies turning with the chassis (C_l, C_r about
    their axes, as in eq. 16) and the wheels."""
    p = model.parameters
    r_c = np.array([model.value("x_c"), model.value("y_c")])
    d_rotation = np.array([[-math.sin(q[2]), -math.cos(q[2])], [math.cos(q[2]), -math.sin(q[2])]])
    v_com = q_dot[:2] + q_dot[2] * d_rotation @ r_c
    c_com = p.C_ch - p.m_ch * float(r_c @ r_c)
    return 0.5 * (p.m_ch * float(v_com @ v_com) + (c_com + p.C_l + p.C_r) * q_dot[2] ** 2 + p.C_l * q_dot[3] ** 2
                  + p.C_r * q_dot[4] ** 2 + p.B_w * float(q_dot[5:] @ q_dot[5:]))


def _gradient(fun, x: np.ndarray, h: float) -> np.ndarray:
    return np.array([(fun(x + h * e) - fun(x - h * e)) / (2 * h) for e in np.eye(x.size)])


def _friction(q_dot: np.ndarray, model: ModelParameters) -> np.ndarray:
    """The joint friction of issue 30 written out: d_v w + (d_c + (d_s - d_c) exp(-(w/w_s)^2)) tanh(w/eps)."""
    out = np.zeros(9)
    for row, g in ((3, "l"), (4, "r"), (5, "w"), (6, "w"), (7, "w"), (8, "w")):
        d_v, d_c = (model.value(n) for n in {"l": ("d_vl", "d_cl"), "r": ("d_vr", "d_cr"), "w": ("d_vw", "d_cw")}[g])
        d_s, w_s, w = model.value(f"d_s{g}"), model.value(f"w_s{g}"), q_dot[row]
        out[row] = d_v * w + (d_c + (d_s - d_c) * math.exp(-((w / w_s) ** 2))) * math.tanh(w / EPSILON)
    return out


def lagrange_forces(coefficients: np.ndarray, t: float, model: ModelParameters):
    """Body-frame ``(q_dot, q_ddot, f)`` at time t of the world motion q(t) = sum_k c_k t^k (9 cubics).

    ``Q = d/dt dT/dq_dot - dT/dq + friction`` by central differences (T is quadratic in q_dot), then
    ``f = J^T Q`` with ``q_dot_world = J q_dot_body``, ``J = diag(R(gamma), 1, ..., 1)``; the body
    accelerations are the time derivatives of the body velocities (as the paper's x_ch_ddot)."""
    powers = lambda s, d: np.array([0 if k < d else math.factorial(k) // math.factorial(k - d) * s ** (k - d)  # noqa: E731
                                    for k in range(coefficients.shape[0])])
    q_of = lambda s: powers(s, 0) @ coefficients  # noqa: E731
    qd_of = lambda s: powers(s, 1) @ coefficients  # noqa: E731
    momentum = lambda s: _gradient(lambda v: _kinetic_energy(q_of(s), v, model), qd_of(s), 1e-3)  # noqa: E731
    tau = 1e-4
    dp = (momentum(t + tau) - momentum(t - tau)) / (2 * tau)
    q, qd_w, qdd_w = q_of(t), qd_of(t), powers(t, 2) @ coefficients
    Q = dp - _gradient(lambda x: _kinetic_energy(x, qd_w, model), q, 1e-5) + _friction(qd_w, model)
    R = _rotation(q[2])
    q_dot, q_ddot, f = qd_w.copy(), qdd_w.copy(), Q.copy()
    q_dot[:2] = R.T @ qd_w[:2]
    q_ddot[:2] = R.T @ qdd_w[:2] + qd_w[2] * np.array([[-R[1, 0], R[0, 0]], [-R[0, 0], -R[1, 0]]]) @ qd_w[:2]
    f[:2] = R.T @ Q[:2]
    return q_dot, q_ddot, f


@settings(max_examples=40, deadline=None)
@given(model=extended_models(), seed=seeds)
def test_off_centre_chassis_and_stribeck_match_independent_lagrange_equations(model, seed):
    rng = np.random.default_rng(seed)
    coefficients = rng.normal(size=(4, 9))
    coefficients[:, 3:] *= 10.0 ** rng.uniform(-2.5, 0.0, 6)  # joint rates in and beyond the Stribeck range
    rows = [lagrange_forces(coefficients, t, model) for t in rng.uniform(-1.0, 1.0, 4)]
    q_dot, q_ddot, expected = (np.array(x) for x in zip(*rows))
    f = generalized_forces_model(q_dot, q_ddot, model)
    scale = max(1.0, np.abs(expected).max())
    assert np.allclose(f, expected, rtol=0, atol=1e-6 * scale)
    # the reference does see the offset: without it the chassis rows differ
    offset_force = model.parameters.m_ch * (abs(model.value("x_c")) + abs(model.value("y_c"))) * \
        max(np.abs(q_dot[:, 2]).max() ** 2, np.abs(q_ddot[:, 2]).max())
    if offset_force > 1e-2 * scale:  # the offset's forces stand out of the reference's tolerance
        paper = generalized_forces(q_dot, q_ddot, model.parameters)
        assert np.abs(paper[:, :3] - expected[:, :3]).max() > 1e-4 * scale


def test_lagrange_reference_reproduces_the_paper_model():
    """The reference itself, without extensions: the paper's Theta p (test_dynamics.py's check)."""
    rng = np.random.default_rng(3)
    model = ModelParameters(PAPER_PARAMETERS)
    rows = [lagrange_forces(rng.normal(size=(4, 9)), t, model) for t in (-0.5, 0.1, 0.7)]
    q_dot, q_ddot, expected = (np.array(x) for x in zip(*rows))
    assert np.allclose(generalized_forces(q_dot, q_ddot, PAPER_PARAMETERS), expected, rtol=0, atol=1e-6 * 1e3)


# --- the paper's model as the special case ----------------------------------------------------------

@settings(max_examples=30, deadline=None)
@given(p=positive_parameters, seed=seeds)
def test_paper_model_is_bit_identical(p, seed):
    rng = np.random.default_rng(seed)
    q_dot, q_ddot = rng.normal(size=(2, 20, 9))
    model = ModelParameters(p)
    assert np.array_equal(generalized_forces_model(q_dot, q_ddot, model), generalized_forces(q_dot, q_ddot, p))
    assert np.array_equal(generalized_forces(q_dot, q_ddot, model), generalized_forces(q_dot, q_ddot, p))
    assert not extension_forces(q_dot, q_ddot, model).any()


@settings(max_examples=30, deadline=None)
@given(p=positive_parameters, w_s=st.floats(0.005, 0.5), seed=seeds)
def test_stribeck_law_with_equal_levels_is_the_papers(p, w_s, seed):
    """d_s = d_c: the breakaway excess vanishes exactly, whatever w_s."""
    rng = np.random.default_rng(seed)
    q_dot, q_ddot = rng.normal(size=(2, 20, 9)) * 10.0 ** rng.uniform(-3, 0, (2, 20, 1))
    extra = {"d_sl": p.d_cl, "d_sr": p.d_cr, "d_sw": p.d_cw, "w_sl": w_s, "w_sr": w_s, "w_sw": w_s}
    model = ModelParameters(p, extra, spec=STRIBECK)
    assert np.array_equal(generalized_forces_model(q_dot, q_ddot, model), generalized_forces(q_dot, q_ddot, p))


@settings(max_examples=30, deadline=None)
@given(model=extended_models(STRIBECK), seed=seeds)
def test_joint_rows_follow_the_friction_law_of_model_spec(model, seed):
    """Without acceleration each joint row is model_spec.joint_friction of its group; far above every
    w_s no breakaway excess is left."""
    rng = np.random.default_rng(seed)
    q_dot = rng.normal(size=(30, 9)) * 10.0 ** rng.uniform(-3, 0, (30, 1))
    f = generalized_forces_model(q_dot, np.zeros_like(q_dot), model)
    for rows, g in ((slice(3, 4), "l"), (slice(4, 5), "r"), (slice(5, 9), "w")):
        d_v, d_c, d_s, w_s = model.friction(g)
        assert np.allclose(f[:, rows], joint_friction(q_dot[:, rows], d_v, d_c, d_s, w_s), rtol=1e-12, atol=1e-12)
    assert np.abs(breakaway_forces(np.full((1, 9), 50.0), model)).max() < 1e-12


@settings(max_examples=40, deadline=None)
@given(seed=seeds, a=st.floats(-3, 3), b=st.floats(-3, 3))
def test_com_offset_forces_are_linear_in_the_first_moments(seed, a, b):
    rng = np.random.default_rng(seed)
    q_dot, q_ddot = rng.normal(size=(2, 15, 9))
    (m1, n1), (m2, n2) = rng.normal(scale=50.0, size=(2, 2))
    lhs = com_offset_forces(q_dot, q_ddot, a * m1 + b * m2, a * n1 + b * n2)
    rhs = a * com_offset_forces(q_dot, q_ddot, m1, n1) + b * com_offset_forces(q_dot, q_ddot, m2, n2)
    assert np.allclose(lhs, rhs, rtol=1e-12, atol=1e-9)
    assert not com_offset_forces(q_dot, q_ddot, 0.0, 0.0).any()
    assert not com_offset_forces(q_dot, q_ddot, m1, n1)[:, 3:].any()  # chassis rows only


def test_com_offset_by_hand():
    """Spinning in place at 1 rad/s with m x_c = 10 kg m: 10 N towards the centre of mass' opposite
    (centripetal); accelerating forward with m y_c = 5 kg m: a yaw torque -5 a."""
    spin = np.zeros((1, 9))
    spin[0, 2] = 1.0
    assert com_offset_forces(spin, np.zeros((1, 9)), 10.0, 0.0)[0, :3] == pytest.approx([-10.0, 0.0, 0.0])
    accel = np.zeros((1, 9))
    accel[0, 0] = 2.0
    assert com_offset_forces(np.zeros((1, 9)), accel, 0.0, 5.0)[0, :3] == pytest.approx([0.0, 0.0, -10.0])


# --- the feed-forward with the extended model ---------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(geom=geometries, mode=modes, model=extended_models(), seed=seeds)
def test_extended_feedforward_reproduces_eq_19_and_holds_the_extra_direction(geom, mode, model, seed):
    rng = np.random.default_rng(seed)
    alpha = configurations(geom, mode, 10, rng)
    s_dot, s_ddot = rng.normal(size=(2, 10, mode.dof)) * 10.0 ** rng.uniform(-2, 0, (2, 10, 1))
    u = feedforward_torques(geom, model, mode, alpha, s_dot, s_ddot)
    q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
    f = generalized_forces_model(q_dot, q_ddot, model)
    H = kinematic_model(geom, mode, alpha)
    lhs = np.einsum("nik,ni->nk", H, f)
    scale = max(1.0, np.abs(lhs).max())
    assert np.allclose(projected_input(geom, mode, alpha, u), lhs, atol=1e-9 * scale)
    net = np.einsum("nim,ni->nm", admissible_basis(geom, mode, alpha), u @ input_matrix(geom).T - f)
    if mode is Mode.LATERAL:
        assert (net[:, 0] <= 1e-9 * scale).all() and (net[:, 1] >= -1e-9 * scale).all()
        assert np.allclose(net[:, 2], 0, atol=1e-9 * scale)
    else:
        assert np.allclose(net, 0, atol=1e-9 * scale)


@settings(max_examples=30, deadline=None)
@given(mode=modes, model=extended_models(base=st.just(PAPER_PARAMETERS)), seed=seeds)
def test_power_balance_of_extended_feedforward(mode, model, seed):
    """Motor power = rate of kinetic energy (off-centre chassis included) + power of the joint friction."""
    geom, p = PROTOTYPE, model.parameters
    rng = np.random.default_rng(seed)
    alpha = configurations(geom, mode, 10, rng)
    s_dot, s_ddot = rng.normal(size=(2, 10, mode.dof)) * 10.0 ** rng.uniform(-2, 0, (2, 10, 1))
    u = feedforward_torques(geom, model, mode, alpha, s_dot, s_ddot)
    q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
    motor_power = np.sum(geom.i_G * u * q_dot[:, 5:], axis=1)
    x_c, y_c = model.value("x_c"), model.value("y_c")
    w, w_dot = q_dot[:, 2], q_ddot[:, 2]
    v_com = q_dot[:, :2] + w[:, None] * np.array([-y_c, x_c])  # body components; |v_com| frame-invariant
    a_com = q_ddot[:, :2] + w_dot[:, None] * np.array([-y_c, x_c])
    c_com = p.C_ch - p.m_ch * (x_c**2 + y_c**2)
    kinetic_rate = (p.m_ch * np.sum(v_com * a_com, axis=1) + (c_com + p.C_l + p.C_r) * w * w_dot
                    + p.C_l * q_dot[:, 3] * q_ddot[:, 3] + p.C_r * q_dot[:, 4] * q_ddot[:, 4]
                    + p.B_w * np.sum(q_dot[:, 5:] * q_ddot[:, 5:], axis=1))
    dissipated = np.array([q_dot[j] @ _friction(q_dot[j], model) for j in range(10)])
    scale = max(1.0, np.abs(motor_power).max())
    assert np.allclose(motor_power, kinetic_rate + dissipated, rtol=0, atol=1e-9 * scale)


def test_paper_model_feedforward_is_bit_identical():
    rng = np.random.default_rng(4)
    for mode in Mode:
        alpha = configurations(PROTOTYPE, mode, 20, rng)
        s_dot, s_ddot = rng.normal(size=(2, 20, mode.dof))
        u = feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, mode, alpha, s_dot, s_ddot)
        assert np.array_equal(feedforward_torques(PROTOTYPE, ModelParameters(PAPER_PARAMETERS), mode, alpha, s_dot,
                                                  s_ddot), u)


def test_delay_does_not_change_the_feedforward():
    rng = np.random.default_rng(5)
    alpha = configurations(PROTOTYPE, Mode.CAR_LIKE, 10, rng)
    s_dot, s_ddot = rng.normal(size=(2, 10, 2))
    delayed = ModelParameters(PAPER_PARAMETERS, delay_s=0.006, spec=ModelSpec(delay=0.006))
    assert np.array_equal(feedforward_torques(PROTOTYPE, delayed, "2", alpha, s_dot, s_ddot),
                          feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, "2", alpha, s_dot, s_ddot))


def test_breakaway_needs_its_parameters():
    with pytest.raises(ValueError, match="missing parameters"):
        ModelParameters(PAPER_PARAMETERS, {"d_sl": 1.0}, spec=STRIBECK)
