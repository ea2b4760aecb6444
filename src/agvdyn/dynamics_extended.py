"""The generalized forces the model beyond the paper adds to Theta p (issue 30, :mod:`agvdyn.model_spec`).

:func:`agvdyn.dynamics.generalized_forces_model` is ``Theta p`` of eq. (15)-(16) (the paper's
forces, :func:`agvdyn.dynamics.generalized_forces`) plus :func:`extension_forces`:

* ``friction: stribeck``: on every joint row of group g (3: left steering, 4: right steering,
  5..8: wheels) the breakaway excess over the paper's Coulomb term,
  ``(d_s - d_c) exp(-(w / w_s)^2) tanh(w / epsilon)`` (:func:`breakaway_forces`), so that the joint's
  friction is :func:`agvdyn.model_spec.joint_friction`;
* ``com_offset``: the chassis rows of an off-centre centre of mass (:func:`com_offset_forces`),
  linear in ``(m_ch x_c, m_ch y_c)``, the equations of :mod:`agvdyn.model_spec` (eq. 14-16 extended).

The torque delay does not enter the forces (see :func:`agvdyn.dynamics.feedforward_torques`).
This module imports no other dynamics module: :mod:`agvdyn.dynamics` builds on it.
"""
from __future__ import annotations

import numpy as np

from agvdyn.kinematics import N_Q
from agvdyn.kinematics.constraints import _rows
from agvdyn.model_spec import FRICTION_GROUPS, ModelParameters, breakaway_weight
from agvdyn.platform import EPSILON

__all__ = ["JOINT_ROWS", "breakaway_forces", "com_offset_forces", "extension_forces"]

#: Rows of q (eq. 14) each friction group acts on: left steering, right steering, the four wheels.
JOINT_ROWS = {"l": slice(3, 4), "r": slice(4, 5), "w": slice(5, 9)}
assert set(JOINT_ROWS) == set(FRICTION_GROUPS)


def _motion(q_dot, q_ddot) -> tuple[np.ndarray, np.ndarray]:
    q_dot = np.atleast_2d(np.asarray(q_dot, dtype=float))
    n = q_dot.shape[0]
    return _rows(q_dot, n, N_Q, "q_dot"), _rows(q_ddot, n, N_Q, "q_ddot")


def breakaway_forces(q_dot, model: ModelParameters, epsilon: float = EPSILON) -> np.ndarray:
    """Breakaway excess ``(d_s - d_c) exp(-(w/w_s)^2) tanh(w/epsilon)`` of every joint ``(N, 9)``
    (zero on the chassis rows), with ``(d_c, d_s, w_s)`` of the joint's group from
    :meth:`ModelParameters.friction`; zero where ``d_s = d_c`` (the paper's law).

    Example: the left steering turning at ``w = 0.05 rad/s`` with ``w_sl = 0.5 rad/s`` (``epsilon =
    0.01``): ``exp(-0.01) tanh(5) = 0.990``, the joint carries ``0.990 (d_sl - d_cl)`` more than the
    paper's ``d_cl tanh(w/epsilon)``; at ``w = 1.5 rad/s`` only ``1.2e-4 (d_sl - d_cl)``.
    """
    qd = np.atleast_2d(np.asarray(q_dot, dtype=float))
    qd = _rows(qd, qd.shape[0], N_Q, "q_dot")
    out = np.zeros(qd.shape)
    for group, rows in JOINT_ROWS.items():
        _, d_c, d_s, w_s = model.friction(group)
        w = qd[:, rows]
        out[:, rows] = (d_s - d_c) * breakaway_weight(w, w_s) * np.tanh(w / epsilon)
    return out


def com_offset_forces(q_dot, q_ddot, m_x_c: float, m_y_c: float) -> np.ndarray:
    """Chassis forces ``(N, 9)`` of a centre of mass at ``(x_c, y_c)`` beyond those of eq. (16), given
    the first moments ``m_x_c = m_ch x_c``, ``m_y_c = m_ch y_c`` (kg m); linear in them
    (:mod:`agvdyn.model_spec`): with ``a_x = x_ddot - y_dot w``, ``a_y = y_ddot + x_dot w``, ``w = gamma_dot``::

        f_x = -m x_c w^2 - m y_c w_dot,   f_y = m x_c w_dot - m y_c w^2,   f_g = m x_c a_y - m y_c a_x

    Example: spinning at ``w = 1 rad/s`` with a first moment ``m x_c = 10 kg m`` pulls the reference
    point with ``f_x = -10 N`` (the centripetal force of the centre of mass).
    """
    qd, qdd = _motion(q_dot, q_ddot)
    w, w_dot = qd[:, 2], qdd[:, 2]
    a_x = qdd[:, 0] - qd[:, 1] * w
    a_y = qdd[:, 1] + qd[:, 0] * w
    w2 = w * w
    out = np.zeros((qd.shape[0], N_Q))
    out[:, 0] = -m_x_c * w2 - m_y_c * w_dot
    out[:, 1] = m_x_c * w_dot - m_y_c * w2
    out[:, 2] = m_x_c * a_y - m_y_c * a_x
    return out


def extension_forces(q_dot, q_ddot, model: ModelParameters, epsilon: float = EPSILON) -> np.ndarray:
    """The forces ``(N, 9)`` the model's extensions add to the paper's Theta p: the breakaway excess
    (``friction: stribeck``) and the off-centre chassis terms (``com_offset``); zero for the paper's model."""
    qd, qdd = _motion(q_dot, q_ddot)
    out = np.zeros((qd.shape[0], N_Q))
    if model.spec.stribeck:
        out += breakaway_forces(qd, model, epsilon)
    if model.spec.com_offset:
        m = model.parameters.m_ch
        out += com_offset_forces(qd, qdd, m * model.value("x_c"), m * model.value("y_c"))
    return out
