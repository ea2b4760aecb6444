"""Payload tracker: recursive estimate of m_ch and C_ch (and the centre-of-mass offset y_c with
``com_offset``) with change detection (issue 31).

Every other parameter is held at its identified value (a parameter file); the rows are the
identification's chassis rows of eq. (19), filtered causally (:mod:`agvdyn.online.rows`). Without
``com_offset`` an off-centre payload is seen through m_ch and C_ch (about the reference point) only,
and its translation-yaw coupling is left in the residuals of the car-like rows.

Algorithm (the reference of the C++ twin: fixed sizes, no allocation per update)
--------------------------------------------------------------------------------
State: ``theta`` (8) = (m_ch, C_ch, b_1..b_6): the two tracked parameters and a bias per kind of row
(:data:`~agvdyn.online.rows.BIAS_KINDS`: x_ch rows of straight and car-like motion, y_ch of lateral,
gamma_ch of rotation, each by the sign of its velocity: motor-torque offsets and the Coulomb friction
the held values miss, in N or N m); ``P`` (8 x 8) its covariance; ``R`` (4) the residual variance of
each noise class: x_ch rows of straight motion, y_ch, gamma_ch, x_ch rows of car-like motion (kinds 7,
8 of :data:`~agvdyn.online.rows.ROW_KINDS`, with the biases of x_ch+ and x_ch-); ``n_rows`` (20) rows
seen per kind (8), per noise class (4) and *tested* per kind (8: rows a CUSUM ran on); four CUSUMs
``g[i, s]`` (parameter i in {m_ch, C_ch}, sign s in {+, -}), each with its start row and the window statistics ``I_w`` (8 x 8) and ``b_w`` (8).

Per row (kind c, noise class ``cl`` = ``(c - 1) // 2`` for kinds 1-6, 3 for 7 and 8, regressor
``phi = (phi_m, phi_C)``, right-hand side ``z``), with ``f = (phi_m, phi_C, e_c)`` (``e_c`` the unit
vector of the row's bias) and ``R_eff = n_corr R_cl`` (the residuals of the filtered rows are
correlated over ~``n_corr`` samples:
``correlation`` for translation, ``rotation_correlation`` for rotation rows; every row counts as
``1 / n_corr`` of an independent one, which keeps the stds honest and the CUSUM calibrated):

0. a kind's first row when its *twin* (the same coordinate, the other sign of its velocity: x_ch+ and x_ch-,
   ...) is warm: its bias starts at the twin's value, variance the twin's plus ``twin_bias_std^2``,
   uncorrelated, and the kind is warm through its twin from then on (its CUSUMs run from this row). A
   torque offset is the same in both directions (both plants: the gamma_ch+ and gamma_ch- biases agree
   within 0.7 N m); a Coulomb misfit is not, hence the std. Before (issue 31), a rotation in a direction
   first driven after a pick-up learnt its bias from zero while warming up, absorbing the change:
   detected 1.5 s after the motion began (seed 5 of the study), now 0.9 s;
1. gating: parameter i is *excited* when ``|phi_i| delta_i >= gate sqrt(R_cl)`` (a change of
   ``delta_i`` would show above the noise in this row);
2. prediction (random walk): ``P_ii += q_i T_s`` for the excited parameters only (directional: no
   wind-up along unexcited directions), capped at the reset variance; ``P_jj += q_b T_s`` for the bias;
3. innovation ``r = z - f . theta``, ``S = f^T P f + R_eff``; ``nis = r^2 / (f^T P f + R_cl)``;
4. CUSUM (once ``n_rows[c] >= warm`` or through its twin; m_ch on excited translation rows, C_ch on
   excited rotation rows only: in car-like rows the yaw and translation misfits mix): ``g[i, s] <- max(0, g[i, s] +
   (s delta_i phi_i r - delta_i^2 phi_i^2 / 2) / R_eff)`` (Page's log-likelihood ratio of a step of
   ``s delta_i`` in parameter i); while ``g > 1`` the rows it runs on join its window statistics
   ``I_w += f f^T / R_eff``, ``b_w += f z / R_eff`` (cleared, start row set, when it rises past 1);
5. update: Kalman gain ``K = P f / S`` with ``K_i = 0`` for unexcited parameters (a Schmidt-type
   directional update), ``theta += K r``, Joseph form ``P = (I - K f^T) P (I - K f^T)^T + K R_eff K^T``;
6. noise: ``R_cl += lambda (r^2 - R_cl)``, ``lambda = max(1 / (n_rows[8 + cl] + 1), T_s / tau_R)``
   (``n_rows[8 + cl]``: every row of the class, so the prior keeps the weight of the rows it was
   not updated on), only from rows the detector tests (the kind warm, the coordinate's own parameter
   excited: a misfit the detector cannot see would otherwise pass for noise, raise ``R`` and blind
   the gate and the CUSUMs; car-like rows also when C_ch is excited: their yaw column is the part the
   model describes worst), frozen while any CUSUM exceeds ``h / 2``, and for rotation rows also while C_ch's
   window is open (a CUSUM above 1: learning the misfit of a small C_ch step, +11 % on a gentle rotation,
   delayed its detection to 1.1 s on MuJoCo; the translation classes are not frozen so: on MuJoCo their
   CUSUMs hover above 1 in turns, and the frozen level came out low and let the car-like rows pull
   C_ch). Why car-like rows are a class of
   their own (issue 31): on the MuJoCo plant the tyres scrub in turns and the car-like rows' residual
   (std ~15 N at the true m_ch, C_ch, correlated over a turn; 5-7 N on our plant) fits C_ch +34..41 %
   high (the rotation rows: within 0.1 %); with the straight rows' noise level (~1.5 N) they dragged
   C_ch up by 20-30 % and the C_ch and m_ch CUSUMs fired 32 times per hour; with their own level they
   weigh ~100x less and the rate is 0 in 4.04 h (seeds 101-112, 201-212; benchmarks/study_tracking.py
   --engine mujoco);
7. detection: CUSUMs above ``h`` are a payload change (a pick-up changes m_ch and C_ch together):
   with the window (``I_w``, ``b_w``) of the highest, m_ch, C_ch and the *young* row biases the window
   saw (fewer than ``YOUNG_WARMUPS x warm`` rows of their kinds: learnt after the change, they may have
   absorbed it) are re-estimated together, priors at their values with variances ``reset_var`` and
   ``bias_std^2``, the other biases held: ``x = A^-1 (prior^-1 theta_S + b_w,S - I_w,S,rest
   theta_rest)``, ``A = diag(prior^-1) + I_w,SS``, ``P_SS = A^-1`` (PX4-style covariance reset),
   decoupled from the rest. A bias the window did not re-estimate that no CUSUM has verified (fewer
   than ``warm`` tested rows of its kinds: learnt from rows too slow to test, e.g. a slow run after a
   pick-up, whose misfit it absorbed) becomes unknown: variance ``bias_std^2``, uncorrelated, value
   kept (before, issue 31: held; m_ch 4.5 % off 3 s after the next brisk run on seed 10 of the study,
   now 1.3 %). One event is logged per CUSUM that fired (detection row, start row =
   change estimate, value and variance before and after); then every CUSUM and window restarts.
   A parameter whose window held no information keeps its value with the reset variance and is
   learnt from the next rows that excite it.

Centre-of-mass offset (``com_offset``; model of :mod:`agvdyn.model_spec`): a ninth state ``s = m_ch y_c``
(index :data:`~agvdyn.online._kernels.OFFSET`, after the biases) with the rows' third column ``phi_y``
(nonzero in car-like rows only: x_c cancels in every mode and has no state). It follows the others:
``f`` gains ``phi_y``; gated with ``delta_y = offset_change x m_ch`` (a y_c change of ``offset_change`` m,
0.05); random walk ``q_y = (offset_walk m_ch)^2`` per s when excited, capped at the reset variance
``(offset_std m_ch)^2`` (0.3 m); ``K_y = 0`` when not excited; no CUSUM of its own (a payload change
is detected by m_ch's and C_ch's), but every reset re-estimates it with m_ch and C_ch (prior at its
value, variance ``(offset_std m_ch)^2``). Reported: ``y_c = s / m_ch`` with the delta-method std
``sqrt(g^T P g)``, ``g = (-s / m_ch^2, 1 / m_ch)`` over (m_ch, s), inf while ``P_ss`` is at its prior or
above (no car-like row has informed it since the start or the last reset); x_c: NaN, inf. Without
``com_offset`` the kernels run the eight states exactly as before (the state's size is a compile-time
constant of each compiled variant). Measured (benchmarks/study_offset_tracking.py, docs/online.md):
the std is optimistic on our plant (|error| / std up to ~8: the car-like rows' model error is
correlated over a whole manoeuvre, longer than ``correlation``).

Constants (``TrackerSettings``): delta = ``change_size`` x the identified value (0.1), gate 1,
n_corr 150 (translation) and 300 (rotation) samples, h 8 (measured without a change: CUSUM maxima
<= 2.0 in 2 h of driving on our plant, <= 4.9 in 3.7 h on MuJoCo; benchmarks/study_tracking.py),
q = (``random_walk`` x value)^2 per s (1e-3), q_b = ``bias_walk``^2 (0.3 N/sqrt s or N m/sqrt s),
reset_var = (``reset_std`` x value)^2
(0.5), tau_R 30 s, warm 250 rows, ``twin_bias_std`` 5 (N or N m). Initial state: the parameter
file's values, std = max(its std,
``initial_std`` x value (0.02)); biases 0 with std ``bias_std`` (30); ``R`` starts at ``noise`` (5^2)
and follows the data from the first row the detector tests.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

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
    twin_bias_std: float = 5.0
    noise: float = 25.0
    max_events: int = 256
    com_offset: bool = False
    offset_change: float = 0.05
    offset_std: float = 0.3
    offset_walk: float = 1e-3

    def __post_init__(self) -> None:
        if not isinstance(self.com_offset, (bool, np.bool_)):
            raise ValueError(f"tracker setting com_offset={self.com_offset!r}: expected true or false")
        for key in ("slip_threshold", "change_size", "gate", "correlation", "rotation_correlation", "threshold", "random_walk", "bias_walk",
                    "reset_std", "noise_time", "initial_std", "bias_std", "twin_bias_std", "noise", "offset_change", "offset_std",
                    "offset_walk"):
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
        k[kern.K_TWIN_VAR] = self.twin_bias_std ** 2
        k[kern.K_TAU_R], k[kern.K_WARM], k[kern.K_DT] = self.noise_time, self.warm_rows, dt
        k[kern.K_DELTA_Y] = self.offset_change * nominal[0]
        k[kern.K_Q_Y] = (self.offset_walk * nominal[0]) ** 2
        k[kern.K_RESET_Y] = (self.offset_std * nominal[0]) ** 2
        return k

    @property
    def states(self) -> int:
        """Size of the state: 8, 9 with the centre-of-mass offset."""
        return kern.NS + int(self.com_offset)


@dataclass(eq=False)
class TrackerState:
    """The mutable state of the tracker (module docstring), carried from one log to the next: ``ns`` = 8
    states, 9 with the centre-of-mass offset (:attr:`TrackerSettings.states`)."""

    theta: np.ndarray
    P: np.ndarray
    R: np.ndarray
    n_rows: np.ndarray
    g: np.ndarray
    Iw: np.ndarray
    bw: np.ndarray
    start: np.ndarray

    @classmethod
    def initial(cls, params: Parameters, std: dict[str, float], settings: TrackerSettings,
                y_c: float = 0.0) -> "TrackerState":
        """The parameter file's m_ch, C_ch (std at least ``initial_std`` x value), row biases 0 (std
        ``bias_std``), noise ``noise``; with the offset, ``m_ch y_c`` from ``y_c`` m with std
        ``max(std['y_c'], offset_change)`` when a finite one is given, else ``offset_std`` (its prior:
        no finite std is reported until a row informs it), by the delta method."""
        nominal = np.array([getattr(params, name) for name in TRACKED])
        given = np.array([std.get(name, 0.0) or 0.0 for name in TRACKED])
        var = np.maximum(given, settings.initial_std * np.abs(nominal)) ** 2
        P = np.diag(np.concatenate([var, np.full(kern.NS - 2, settings.bias_std ** 2)]))
        theta = np.concatenate([nominal, np.zeros(kern.NS - 2)])
        ns = settings.states
        if settings.com_offset:
            sd = std.get("y_c", math.inf)
            if not math.isfinite(y_c) or (sd is not None and sd < 0):
                raise ValueError(f"tracker: y_c={y_c!r} with std {sd!r}: expected a finite centre-of-mass offset in m "
                                 "and a std >= 0 (inf or None: none given)")
            sd = max(sd, settings.offset_change) if sd is not None and math.isfinite(sd) else settings.offset_std
            theta = np.append(theta, nominal[0] * y_c)
            P = np.pad(P, ((0, 1), (0, 1)))
            P[kern.OFFSET, kern.OFFSET] = (nominal[0] * sd) ** 2 + (y_c ** 2) * var[0]
            P[0, kern.OFFSET] = P[kern.OFFSET, 0] = y_c * var[0]
        return cls(theta, P, np.full(kern.CLASSES, settings.noise), np.zeros(kern.COUNTS),
                   np.zeros((2, 2)), np.zeros((2, 2, ns, ns)), np.zeros((2, 2, ns)), np.zeros((2, 2)))


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


class TrackerRun(NamedTuple):
    """One log through the tracker: per sample the state ``theta`` (N, ns) and its variances ``var``
    (N, ns), ``nis`` (N,) (NaN without a row), event flags ``event`` (N,), the ``events``, and
    ``offset`` (N, 2): y_c and its std (:func:`~agvdyn.online._kernels.offset_estimate`; (N, 0)
    without the centre-of-mass offset)."""

    theta: np.ndarray
    var: np.ndarray
    nis: np.ndarray
    event: np.ndarray
    events: list[ChangeEvent]
    offset: np.ndarray


def check_rows(rows: OnlineRows, state: TrackerState, settings: TrackerSettings) -> None:
    """ValueError unless the rows' columns, the state's sizes and the settings agree (m_ch y_c's column
    and state exactly when ``settings.com_offset``)."""
    cols, ns = rows.phi.shape[1], state.theta.size
    if (state.R.shape, state.n_rows.shape) != ((kern.CLASSES,), (kern.COUNTS,)):
        raise ValueError(f"tracker state: R of shape {state.R.shape} and n_rows of {state.n_rows.shape}: expected "
                         f"({kern.CLASSES},) and ({kern.COUNTS},) (TrackerState.initial)")
    if (cols, ns) != (2 + settings.com_offset, settings.states):
        raise ValueError(f"tracker: rows with {cols} regressor columns and a state of {ns} for com_offset="
                         f"{settings.com_offset}: expected {2 + settings.com_offset} and {settings.states} "
                         "(causal_rows(..., com_offset=) and TrackerState.initial with the same settings)")


def change_events(rows: OnlineRows, raw: Any, source: str) -> list[ChangeEvent]:
    """The events of one log from their raw values ``(sample, start, parameter, sign, before, before_var,
    after, after_var)``: detection time when the row was complete, change time less the group delay."""
    late = rows.lookahead * rows.dt
    return [ChangeEvent(TRACKED[int(p)], float(rows.t[int(k)] + late), float(rows.t[int(start)] - rows.group_delay),
                        int(sign), float(before), math.sqrt(before_var), float(after), math.sqrt(after_var), source)
            for k, start, p, sign, before, before_var, after, after_var in raw]


def run_tracker(rows: OnlineRows, state: TrackerState, settings: TrackerSettings, nominal: np.ndarray,
                source: str = "") -> TrackerRun:
    """One log's rows through the compiled tracker (``state`` updated in place)."""
    check_rows(rows, state, settings)
    n, ns = rows.n, state.theta.size
    out_theta, out_var, out_nis = np.zeros((n, ns)), np.zeros((n, ns)), np.zeros(n)
    out_event = np.zeros(n, dtype=np.int64)
    out_offset = np.zeros((n if settings.com_offset else 0, 2))
    events = np.zeros((settings.max_events, kern.E_NCOLS))
    k = settings.constants(nominal, rows.dt)
    count = kern.track_rows(np.ascontiguousarray(rows.phi), rows.z, rows.kind.astype(np.int64), k, state.theta,
                            state.P, state.R, state.n_rows, state.g, state.Iw, state.bw, state.start, out_theta,
                            out_var, out_nis, out_event, out_offset, events, 0)
    raw = events[:min(count, settings.max_events)][:, [kern.E_K, kern.E_START, kern.E_PARAM, kern.E_SIGN, kern.E_BEFORE,
                                                      kern.E_BEFORE_VAR, kern.E_AFTER, kern.E_AFTER_VAR]]
    return TrackerRun(out_theta, out_var, out_nis, out_event, change_events(rows, raw, source), out_offset)
