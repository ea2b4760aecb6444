"""Payload tracker: recursive estimate of m_ch and C_ch with change detection (issue 31).

Every other parameter is held at its identified value (a parameter file); the rows are the
identification's chassis rows of eq. (19), filtered causally (:mod:`agvdyn.online.rows`). The
identification model has no centre-of-mass offset yet (issue 30), so x_c and y_c are not tracked:
an off-centre payload is seen through m_ch and C_ch (about the reference point) only, and its
translation-yaw coupling is left in the residuals.

Algorithm (the reference of the C++ twin: fixed sizes, no allocation per update)
--------------------------------------------------------------------------------
State: ``theta`` (8) = (m_ch, C_ch, b_1..b_6): the two tracked parameters and a bias per kind of row
(:data:`~agvdyn.online.rows.ROW_KINDS`: x_ch rows of straight and car-like motion, y_ch of lateral,
gamma_ch of rotation, each by the sign of its velocity: motor-torque offsets and the Coulomb friction
the held values miss, in N or N m); ``P`` (8 x 8) its covariance; ``R`` (3) the residual variance of
the x_ch, y_ch and gamma_ch rows; ``n_rows`` (9) rows seen per kind (6) and per coordinate (3); four
CUSUMs ``g[i, s]`` (parameter i in {m_ch, C_ch}, sign s in {+, -}), each with its start row and the
window statistics ``I_w`` (8 x 8) and ``b_w`` (8).

Per row (kind c, coordinate class ``cl = (c - 1) // 2``, regressor ``phi = (phi_m, phi_C)``, right-hand
side ``z``), with ``f = (phi_m, phi_C, e_c)`` (``e_c`` the unit vector of the row's bias) and
``R_eff = n_corr R_cl`` (the residuals of the filtered rows are correlated over ~``n_corr`` samples:
``correlation`` for translation, ``rotation_correlation`` for rotation rows; every row counts as
``1 / n_corr`` of an independent one, which keeps the stds honest and the CUSUM calibrated):

1. gating: parameter i is *excited* when ``|phi_i| delta_i >= gate sqrt(R_cl)`` (a change of
   ``delta_i`` would show above the noise in this row);
2. prediction (random walk): ``P_ii += q_i T_s`` for the excited parameters only (directional: no
   wind-up along unexcited directions), capped at the reset variance; ``P_jj += q_b T_s`` for the bias;
3. innovation ``r = z - f . theta``, ``S = f^T P f + R_eff``; ``nis = r^2 / (f^T P f + R_cl)``;
4. CUSUM (once ``n_rows[c] >= warm``; m_ch on excited translation rows, C_ch on excited rotation rows
   only: in car-like rows the yaw and translation misfits mix): ``g[i, s] <- max(0, g[i, s] +
   (s delta_i phi_i r - delta_i^2 phi_i^2 / 2) / R_eff)`` (Page's log-likelihood ratio of a step of
   ``s delta_i`` in parameter i); while ``g > 1`` the rows it runs on join its window statistics
   ``I_w += f f^T / R_eff``, ``b_w += f z / R_eff`` (cleared, start row set, when it rises past 1);
5. update: Kalman gain ``K = P f / S`` with ``K_i = 0`` for unexcited parameters (a Schmidt-type
   directional update), ``theta += K r``, Joseph form ``P = (I - K f^T) P (I - K f^T)^T + K R_eff K^T``;
6. noise: ``R_cl += lambda (r^2 - R_cl)``, ``lambda = max(1 / (n_rows[6 + cl] + 1), T_s / tau_R)``
   (``n_rows[6 + cl]``: every row of the coordinate, so the prior keeps the weight of the rows it was
   not updated on), only from rows the detector tests (the kind warm, the coordinate's own parameter
   excited: a misfit the detector cannot see would otherwise pass for noise, raise ``R`` and blind
   the gate and the CUSUMs), frozen while any CUSUM exceeds ``h / 2``;
7. detection: CUSUMs above ``h`` are a payload change (a pick-up changes m_ch and C_ch together):
   with the window (``I_w``, ``b_w``) of the highest, m_ch, C_ch and the *young* row biases the window
   saw (fewer than ``YOUNG_WARMUPS x warm`` rows of their kind: learnt after the change, they may have
   absorbed it) are re-estimated together, priors at their values with variances ``reset_var`` and
   ``bias_std^2``, the other biases held: ``x = A^-1 (prior^-1 theta_S + b_w,S - I_w,S,rest
   theta_rest)``, ``A = diag(prior^-1) + I_w,SS``, ``P_SS = A^-1`` (PX4-style covariance reset),
   decoupled from the rest. One event is logged per CUSUM that fired (detection row, start row =
   change estimate, value and variance before and after); then every CUSUM and window restarts.
   A parameter whose window held no information keeps its value with the reset variance and is
   learnt from the next rows that excite it.

Constants (``TrackerSettings``): delta = ``change_size`` x the identified value (0.1), gate 1,
n_corr 150 (translation) and 300 (rotation) samples, h 8 (measured without a change: CUSUM maxima
<= 5.5 in 2 h of driving; benchmarks/study_tracking.py), q = (``random_walk`` x value)^2 per s
(1e-3), q_b = ``bias_walk``^2 (0.3 N/sqrt s or N m/sqrt s), reset_var = (``reset_std`` x value)^2
(0.5), tau_R 30 s, warm 250 rows. Initial state: the parameter file's values, std = max(its std,
``initial_std`` x value (0.02)); biases 0 with std ``bias_std`` (30); ``R`` starts at ``noise`` (5^2)
and follows the data from the first row the detector tests.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agvdyn.online import _kernels as kern
from agvdyn.online.rows import TRACKED, OnlineRows
from agvdyn.platform import Parameters
from agvdyn.row_rules import RowSettings

__all__ = ["TrackerSettings", "TrackerState", "ChangeEvent", "run_tracker"]


@dataclass(frozen=True)
class TrackerSettings:
    """Constants of the tracker (module docstring); relative ones are fractions of the identified values."""

    rules: RowSettings = RowSettings()
    slip_threshold: float = 0.05
    change_size: float = 0.1
    gate: float = 1.0
    correlation: float = 150.0
    rotation_correlation: float = 300.0
    threshold: float = 8.0
    random_walk: float = 1e-3
    bias_walk: float = 0.3
    reset_std: float = 0.5
    noise_time: float = 30.0
    warm_rows: int = 250
    initial_std: float = 0.02
    bias_std: float = 30.0
    noise: float = 25.0
    max_events: int = 256

    def __post_init__(self) -> None:
        for key in ("slip_threshold", "change_size", "gate", "correlation", "rotation_correlation", "threshold", "random_walk", "bias_walk",
                    "reset_std", "noise_time", "initial_std", "bias_std", "noise"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"tracker setting {key}={v!r}: expected a finite number > 0")
        if not (isinstance(self.warm_rows, int) and self.warm_rows >= 0 and self.max_events >= 1):
            raise ValueError(f"tracker settings warm_rows={self.warm_rows!r}, max_events={self.max_events!r}: "
                             "expected integers >= 0 and >= 1")

    def constants(self, nominal: np.ndarray, dt: float) -> np.ndarray:
        """The constants vector of the compiled update (layout: :mod:`._kernels`)."""
        k = np.zeros(kern.K_NCONST)
        k[kern.K_DELTA_M], k[kern.K_DELTA_C] = self.change_size * nominal
        k[kern.K_Q_M], k[kern.K_Q_C] = (self.random_walk * nominal) ** 2
        k[kern.K_Q_B] = self.bias_walk ** 2
        k[kern.K_RESET_M], k[kern.K_RESET_C] = (self.reset_std * nominal) ** 2
        k[kern.K_CORR], k[kern.K_GATE], k[kern.K_H] = self.correlation, self.gate, self.threshold
        k[kern.K_CORR_G] = self.rotation_correlation
        k[kern.K_BIAS_VAR] = self.bias_std ** 2
        k[kern.K_TAU_R], k[kern.K_WARM], k[kern.K_DT] = self.noise_time, self.warm_rows, dt
        return k


@dataclass(eq=False)
class TrackerState:
    """The mutable state of the tracker (module docstring), carried from one log to the next."""

    theta: np.ndarray
    P: np.ndarray
    R: np.ndarray
    n_rows: np.ndarray = field(default_factory=lambda: np.zeros(9))
    g: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))
    Iw: np.ndarray = field(default_factory=lambda: np.zeros((2, 2, kern.NS, kern.NS)))
    bw: np.ndarray = field(default_factory=lambda: np.zeros((2, 2, kern.NS)))
    start: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))

    @classmethod
    def initial(cls, params: Parameters, std: dict[str, float], settings: TrackerSettings) -> "TrackerState":
        nominal = np.array([getattr(params, name) for name in TRACKED])
        given = np.array([std.get(name, 0.0) or 0.0 for name in TRACKED])
        var = np.maximum(given, settings.initial_std * np.abs(nominal)) ** 2
        P = np.diag(np.concatenate([var, np.full(kern.NS - 2, settings.bias_std ** 2)]))
        return cls(np.concatenate([nominal, np.zeros(kern.NS - 2)]), P, np.full(3, settings.noise))


@dataclass(frozen=True)
class ChangeEvent:
    """A detected change of one parameter: when the row that crossed the threshold was complete
    (``t_detected``), the estimated time of the change (``t_change_estimate``: the CUSUM's start,
    less the filters' group delay), the sign of the step and the estimate with its std before and
    right after the reset."""

    parameter: str
    t_detected: float
    t_change_estimate: float
    sign: int
    before: float
    before_std: float
    after: float
    after_std: float
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "t_detected": self.t_detected, "t_change_estimate": self.t_change_estimate,
                "sign": self.sign, "before": {"value": self.before, "std": self.before_std},
                "after": {"value": self.after, "std": self.after_std}, "source": self.source}


def run_tracker(rows: OnlineRows, state: TrackerState, settings: TrackerSettings, nominal: np.ndarray,
                source: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[ChangeEvent]]:
    """One log's rows through the compiled tracker (``state`` updated in place): estimates (N, 5),
    variances (N, 5), NIS (N,), event flags (N,) and the events."""
    n = rows.n
    out_theta, out_var, out_nis = np.zeros((n, kern.NS)), np.zeros((n, kern.NS)), np.zeros(n)
    out_event = np.zeros(n, dtype=np.int64)
    events = np.zeros((settings.max_events, kern.E_NCOLS))
    k = settings.constants(nominal, rows.dt)
    count = kern.track_rows(np.ascontiguousarray(rows.phi), rows.z, rows.kind.astype(np.int64), k, state.theta,
                            state.P, state.R, state.n_rows, state.g, state.Iw, state.bw, state.start, out_theta,
                            out_var, out_nis, out_event, events, 0)
    found = []
    late = rows.lookahead * rows.dt
    for e in events[:min(count, settings.max_events)]:
        found.append(ChangeEvent(TRACKED[int(e[kern.E_PARAM])], float(rows.t[int(e[kern.E_K])] + late),
                                 float(rows.t[int(e[kern.E_START])] - rows.group_delay), int(e[kern.E_SIGN]),
                                 float(e[kern.E_BEFORE]), math.sqrt(e[kern.E_BEFORE_VAR]), float(e[kern.E_AFTER]),
                                 math.sqrt(e[kern.E_AFTER_VAR]), source))
    return out_theta, out_var, out_nis, out_event, found
