"""Drive controller: feed-forward of eq. (21) plus cascaded feedback (after Pucher et al. 2018).

The feed-forward ``u_ff`` is computed once along the planned trajectory, vectorised, with the
controller's own parameter estimate (``agvdyn.dynamics.feedforward_torques``). The feedback runs
every ``T_s`` on sensor readings only (quantized encoders and steering angles):

- wheel speed loops, one per wheel: ``kv (beta_dot_d - beta_dot_f) + kp e_beta``, with
  ``beta_dot_f`` the low-passed difference quotient of the encoder; the position term is the
  integral part of the speed loop, and its references restart from the measured wheel angles
  at every mode switch. The loops act on the mean of a side's front and rear wheel; their
  difference is, by the rolling constraints, the steering angle of that side
  (``beta_f - beta_r = -2 s a alpha / r`` at rest and while driving with ``v_y = 0``), which tyre
  slip makes disagree with the steering sensor, so it is left to the steering loop (with both,
  the loops fight and the steering drifts by up to 0.1 rad in the lane change). In mode 3 and
  while aligning near it (both sides within 0.3 rad of the stops) the difference also measures
  the lateral motion of the chassis; there the part the steering sensor does not explain is fed
  back too, which holds the chassis while the wheels turn into their stops;
- steering loops, one per side: a PID steering torque ``T_s = k_a e + d_a e_dot + k_i int e`` on ``e = alpha_d - alpha``
  produced by a differential torque of the front and rear wheel of that side: the longitudinal
  wheel forces act at the offset ``a`` from the steering axis, so a torque pair ``+-dM`` on the
  motors turns the side by ``-s_i h_i a i_G dM / r`` per wheel (``s_i`` side sign, ``h_i`` = +1
  front, -1 rear, PLATFORM.md);
- the drive limits every motor torque to ``torque_limit`` (plant setting).

The chassis pose is not fed back (the identification runs on odometry alone, sec. 6.2).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ControllerSettings:
    """Feedback gains (motor side, N m) and velocity filters.

    wheel_velocity_gain : N m per rad/s of wheel-side speed error.
    wheel_position_gain : N m per rad of wheel-side angle error (integral part of the speed loop).
    steering_gain : steering torque (N m, steering side) per rad of steering error.
    steering_damping : steering torque per rad/s of steering-rate error.
    steering_integral : steering torque per rad s of integrated steering error (holds the steering
        against stiction and feed-forward errors), limited to +- ``steering_integral_limit`` N m;
        errors within +- ``steering_deadband`` (rad, a few sensor counts) are not integrated, so that
        the integral does not hunt against stiction while the steering stands still.
    wheel_filter, steering_filter : time constants (s) of the first-order filters of the
        difference quotients of the encoders.
    feedback : False runs the feed-forward alone.
    """

    wheel_velocity_gain: float = 2.5
    wheel_position_gain: float = 25.0
    steering_gain: float = 600.0
    steering_damping: float = 15.0
    steering_integral: float = 3000.0
    steering_integral_limit: float = 20.0
    steering_deadband: float = 0.002
    wheel_filter: float = 0.004
    steering_filter: float = 0.015
    feedback: bool = True

    def __post_init__(self) -> None:
        for key in ("wheel_velocity_gain", "wheel_position_gain", "steering_gain", "steering_damping",
                    "steering_integral", "steering_integral_limit", "steering_deadband", "wheel_filter",
                    "steering_filter"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"controller setting {key}={v!r}: expected a finite number >= 0")

    def gains(self, geom) -> np.ndarray:
        """Vector of the compiled controller: gains, filters and the steering-torque factor r / (2 a i_G)."""
        return np.array([
            self.wheel_velocity_gain, self.wheel_position_gain, self.steering_gain, self.steering_damping,
            self.wheel_filter, self.steering_filter, geom.r / (2 * geom.a * geom.i_G), float(self.feedback),
            self.steering_integral, self.steering_integral_limit, self.steering_deadband, geom.a / geom.r,
        ])

    def to_dict(self) -> dict:
        return dict(self.__dict__)


#: Controller state: previous beta (4), alpha (2), filtered beta_dot (4), alpha_dot (2), started flag,
#: steering integrals (2), wheel-angle reference offsets (4).
STATE_SIZE = 19


from agvdyn.simulation._kernels import controller_step  # noqa: E402,F401  (compiled)

__all__ = ["ControllerSettings", "STATE_SIZE", "controller_step"]
