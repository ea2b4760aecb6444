"""Kinematics of the platform: rolling constraints, odometry, ICR, motion modes, H_k.

Conventions (PLATFORM.md): ``alpha`` is ``(N, 2)`` = ``(alpha_l, alpha_r)``, the headings of the
front wheels; the rear wheels are mirrored. ``q_dot`` is ``(N, 9)`` =
``(v_x, v_y, omega, alpha_l_dot, alpha_r_dot, beta_fl_dot, beta_rl_dot, beta_fr_dot, beta_rr_dot)``
with body-frame chassis velocities. Every function takes a leading sample axis.

Two stages: :mod:`.constraints` (eq. 1-2, the ICR relation eq. 6-8, modes eq. 9) and
:mod:`.models` (H_k, eq. 4 and 10-13).
"""
from __future__ import annotations

from agvdyn.kinematics.constraints import (
    MODE_TOLERANCE,
    N_Q,
    STOP_TOLERANCE,
    Mode,
    as_alpha,
    check_mode,
    constraint_matrix,
    constraint_matrix_into,
    detect_mode,
    icr_residual,
    icr_state,
    icr_state_trig,
    max_virtual_angle,
    nominal_steering,
    steering_from_virtual,
    steering_from_virtual_derivatives,
    virtual_from_steering,
    wheel_frame,
    wheel_headings,
)
from agvdyn.kinematics.models import (
    admissible_basis,
    car_like_model_into,
    joint_motion,
    kinematic_model,
    kinematic_model_dot,
)

__all__ = [
    "MODE_TOLERANCE", "N_Q", "STOP_TOLERANCE", "Mode", "as_alpha", "check_mode", "constraint_matrix",
    "constraint_matrix_into", "detect_mode", "icr_residual", "icr_state", "icr_state_trig", "max_virtual_angle",
    "nominal_steering", "steering_from_virtual", "steering_from_virtual_derivatives", "virtual_from_steering",
    "wheel_frame", "wheel_headings", "admissible_basis", "car_like_model_into", "joint_motion", "kinematic_model",
    "kinematic_model_dot",
]
