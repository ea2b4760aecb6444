"""Planner of the identification sequence (sec. 6.2) for a vehicle in a floor rectangle.

The sequence keeps the paper's order and modes (steer left, steer right, straight, rotation, with
the alignments at rest between them); each of the four phases is one period of a finite Fourier
series (sec. 6.2) that starts and ends at rest. The planner chooses, jointly for the four phases,
the duration of each phase (within the total duration), its number of harmonics and its
coefficients, subject to the velocity, acceleration and feed-forward torque limits
(:class:`~agvdyn.trajectories.limits.Limits`), the steering stops and the floor length.

What is optimised
-----------------
The rows of eq. (19) of one phase are linear in ``z = (s_ddot, s_dot, sign s_dot, 1)``: the
regressor ``H_k^T Theta`` of a phase with constant ``H_k`` (modes 1, 4 and straight) is
``z^T P`` with a constant ``(4, 14)`` matrix ``P`` (ten parameters, B_w known, and the four
motor-torque offsets the identification estimates with them). The information matrix of the
sequence is therefore ``F = sum_phases P^T M P / sigma^2`` with the phase's ``4 x 4`` moment
matrix ``M = sum_t w_t z_t z_t^T`` and the noise level ``sigma`` of its generalized coordinate
(:class:`NoiseLevels`). The rows' effective variance grows with the acceleration (the plant's
model error: tyre slip and twist), so the covariance is the sandwich ``F^-1 Omega F^-1`` of the
identification's one-weight-per-coordinate estimator, ``Omega`` the moments times each row's
variance factor; calibrated on the jackknife std of the simulator (docs/planning.md). The weight ``w``
of a row (:func:`_row_weights`) keeps the plan where the model is true: rows below ``validity``
times the identification's stiction threshold earn no credit (slow motion: stick/slip), nor do
rows the identification keeps within ``reversal_window`` of a velocity reversal (the reversal's
stick, spread by the zero-phase filter); the time spent in either is penalised.

Objectives (``PlanSettings.objective``), each plus those validity penalties:

* ``std`` (default): the mean of ``log(std_i / |p_i|)`` over the ten parameters (the predicted
  relative standard deviations, from the sandwich), with a penalty on every parameter whose predicted
  std exceeds its margin (``reference_margin``, per parameter ``parameter_margins``) times the one of
  the default sequence in the same floor and
  duration, and on ``cond(Theta_1w^T Theta_1w)`` above ``cond_target``. It trades conditioning
  against precision and the model's validity.
* ``d-optimal``: ``log det`` of the parameters' covariance (the sandwich's block of the ten).
* ``cond``: ``log cond(Theta_1w^T Theta_1w)`` of the column-scaled regressor (eq. 25).

The gradient is analytic (chain rule through the moments, the Fourier basis and the scaling of
each phase to its most restrictive limit), everything is vectorised over time, and
``scipy.optimize.minimize`` (L-BFGS-B) runs from several random starts (harmonics drawn per
start) in parallel processes. The result is evaluated exactly on the ``T_s`` grid with the
identification's stiction mask and guard (:func:`evaluate_sequence`), next to the default
sequence in the same floor (:func:`default_for_floor`).
"""
from agvdyn.trajectories.planner.evaluation import SequenceEvaluation, default_for_floor, evaluate_sequence
from agvdyn.trajectories.planner.figure import plan_figure
from agvdyn.trajectories.planner.optimize import plan
from agvdyn.trajectories.planner.result import Candidate, Plan, PhaseDesign, combine
from agvdyn.trajectories.planner.problem import _phase_models, _Problem  # noqa: F401  (tests)
from agvdyn.trajectories.planner.settings import FREE, OBJECTIVES, PHASES, SEARCHES, NoiseLevels, PlanSettings, parse_floor

__all__ = ["Candidate", "FREE", "NoiseLevels", "PlanSettings", "SEARCHES", "PhaseDesign", "SequenceEvaluation", "Plan", "OBJECTIVES", "PHASES",
           "plan", "combine", "evaluate_sequence", "default_for_floor", "plan_figure", "parse_floor"]
