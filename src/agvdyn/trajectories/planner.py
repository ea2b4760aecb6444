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
(:class:`NoiseLevels`, growing with the acceleration in translation: tyre slip). The weight ``w``
of a row (:func:`_row_weights`) keeps the plan where the model is true: rows below ``validity``
times the identification's stiction threshold earn no credit (slow motion: stick/slip), nor do
rows the identification keeps within ``reversal_window`` of a velocity reversal (the reversal's
stick, spread by the zero-phase filter); the time spent in either is penalised.

Objectives (``PlanSettings.objective``), each plus those validity penalties:

* ``std`` (default): the mean of ``log(std_i / |p_i|)`` over the ten parameters (the predicted
  relative standard deviations, from ``F^-1``), with a penalty on every parameter whose predicted
  std exceeds ``reference_margin`` times the one of the default sequence in the same floor and
  duration, and on ``cond(Theta_1w^T Theta_1w)`` above ``cond_target``. It trades conditioning
  against precision and the model's validity.
* ``d-optimal``: ``log det`` of the parameters' covariance (offsets eliminated).
* ``cond``: ``log cond(Theta_1w^T Theta_1w)`` of the column-scaled regressor (eq. 25).

The gradient is analytic (chain rule through the moments, the Fourier basis and the scaling of
each phase to its most restrictive limit), everything is vectorised over time, and
``scipy.optimize.minimize`` (L-BFGS-B) runs from several random starts (harmonics drawn per
start) in parallel processes. The result is evaluated exactly on the ``T_s`` grid with the
identification's stiction mask and guard (:func:`evaluate_sequence`), next to the default
sequence in the same floor (:func:`default_for_floor`).
"""
from __future__ import annotations

import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import scipy.optimize

from agvdyn.dynamics import feedforward_torques, projected_regressor
from agvdyn.kinematics import Mode, joint_motion, kinematic_model, nominal_steering
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, SAMPLE_TIME, Geometry, Parameters
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import default_excitation, default_periods, identification_sequence
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.limits import FloorSpace, Limits, check_limits, floor_space, limit_report
from agvdyn.trajectories.segments import Trajectory, alignment

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["NoiseLevels", "PlanSettings", "PhaseDesign", "SequenceEvaluation", "Plan", "OBJECTIVES", "PHASES",
           "plan", "evaluate_sequence", "default_for_floor", "plan_figure", "parse_floor"]

#: Objectives of :func:`plan`.
OBJECTIVES = ("std", "d-optimal", "cond")
Objective = Literal["std", "d-optimal", "cond"]

#: The four phases of sec. 6.2 in their execution order: (name, mode).
PHASES: tuple[tuple[str, Mode], ...] = (
    ("steer_left", Mode.PARKING), ("steer_right", Mode.PARKING), ("straight", Mode.STRAIGHT),
    ("rotation", Mode.ROTATION),
)
#: The ten parameters the sequence identifies (B_w is known, sec. 6.3).
FREE = PARAMETER_NAMES[:10]
_OFFSETS = 4


@dataclass(frozen=True)
class NoiseLevels:
    """Effective noise of one row of eq. (19) (2 ms rows) per generalized coordinate: N m for the
    steering and the yaw, N for x_ch and y_ch.

    Translations add tyre slip: the level of an x_ch or y_ch row grows as
    ``sqrt(x_ch^2 + (slip a^2)^2)`` with the chassis acceleration a (:meth:`growth`).

    The defaults are the residual RMS of each coordinate in the identification of the default
    sequence on the simulator (0.17, 0.22 N m steering, 1.55 N straight, 1.16 N m rotation), times
    the square root of the variance inflation of the HAC uncertainty over the classic one (about
    4 for the steering, 7 for the chassis: the residuals are correlated over ~0.2 s). With them
    the predicted standard deviations of the default sequence match the HAC ones of
    ``agvdyn identify`` within about 30 %. Only their ratios matter for the plan.
    """

    alpha_l: float = 0.7
    alpha_r: float = 0.85
    alpha_v: float = 0.8
    x_ch: float = 12.0
    y_ch: float = 12.0
    gamma_ch: float = 8.4
    slip: float = 55.0

    def __post_init__(self) -> None:
        for key, value in self.__dict__.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise TrajectoryError(f"noise level {key}={value!r}: expected a finite number >= 0")
            if key != "slip" and value == 0:
                raise TrajectoryError(f"noise level {key}={value!r}: expected a finite number > 0")

    def of(self, coordinate: str) -> float:
        return float(getattr(self, coordinate))

    def growth(self, coordinate: str) -> float:
        """Growth of the row noise with the square of the acceleration (N per (m/s^2)^2): x_ch and
        y_ch only. The tyres slip in proportion to the force they transmit, so the odometry (wheel
        angles) sees ``a (1 + slip)``: a model error of about ``7 a^2`` N RMS on the simulator's
        straight motion (``slip`` is that, times the same HAC factor as the levels)."""
        return self.slip if coordinate in ("x_ch", "y_ch") else 0.0


@dataclass(frozen=True)
class PlanSettings:
    """Settings of :func:`plan` (all tuning constants in one frozen place).

    objective : ``std`` (default), ``d-optimal`` or ``cond`` (see the module docstring).
    starts : random starts of the optimiser; ``seed`` their generator; ``workers`` processes
        (None: up to two, one per core).
    harmonics : (fewest, most) harmonics of a phase; each start draws them per phase, capped so
        that the highest harmonic stays below ``max_frequency`` (rad/s, well inside the
        identification filter's 40 rad/s).
    min_phase : shortest phase, s.
    steering_excursion : largest |alpha| of the steering phases, rad (stops at pi/2).
    max_heading : largest |gamma_ch| of the rotation, rad.
    max_speed : largest chassis speed of the straight motion, m/s (below ``Limits.speed``): faster,
        tyre scrub and slip put slowly varying errors into the straight's rows (on the simulator the
        HAC std of m_ch grew 1.5x at 1.4 m/s although the prediction fell).
    max_acceleration : largest chassis acceleration of the straight motion, m/s^2 (below
        ``Limits.acceleration``), for the same reason (tyre slip grows with the force).
    reference_margin : the ``std`` objective penalises a predicted std above ``reference_margin``
        times the default sequence's: the prediction of the chassis rows is optimistic where a plan
        leaves the default's regime (slowly varying tyre errors inflate the HAC std).
    steering_threshold, stiction_threshold, stiction_guard : the identification's stiction
        thresholds (rad/s steering; m/s, rad/s chassis) and guard (s) used to predict which rows
        it keeps (the defaults of ``IdentificationSettings``: 0.1, 0.05, 2 / 40 rad/s).
    validity : rows count in the objective from ``validity`` times the threshold on (smooth step
        of relative width ``validity_width``): slow motion is where the friction model is least true.
    band_penalty : weight of the share of the phases' time spent below that speed.
    reversal_window, reversal_penalty : rows within ``reversal_window`` s of a velocity reversal
        that the identification keeps carry the reversal's stick/slip, spread by its zero-phase
        filter (on the simulator they biased C_l, C_r by -3 to -11 %); they earn no credit and
        their share of the time costs ``reversal_penalty`` (see :func:`_row_weights`).
    cond_target, reference_penalty : the ``std`` objective's penalties (see the module docstring),
        ``reference_penalty`` the weight of both.
    margin : share of every limit the plan may use (the rest for tracking and rounding).
    pause, align_rate, align_acceleration : the alignments at rest between the phases.
    grid : time step of the optimiser's evaluation, s (the result is evaluated at ``T_s``).
    max_iterations : of L-BFGS-B per start.
    noise : :class:`NoiseLevels`. torque_offsets : the identification estimates motor-torque offsets.
    """

    objective: str = "std"
    starts: int = 6
    seed: int = 0
    workers: int | None = None
    harmonics: tuple[int, int] = (4, 30)
    max_frequency: float = 10.0
    min_phase: float = 6.0
    steering_excursion: float = 1.2
    max_heading: float = math.pi
    max_speed: float = 0.8
    max_acceleration: float = 0.6
    reference_margin: float = 0.7
    steering_threshold: float = 0.1
    stiction_threshold: float = 0.05
    stiction_guard: float = 0.05
    validity: float = 2.0
    validity_width: float = 0.15
    band_penalty: float = 0.5
    reversal_window: float = 0.25
    reversal_penalty: float = 10.0
    cond_target: float = 6.0
    reference_penalty: float = 20.0
    margin: float = 0.97
    pause: float = 0.5
    align_rate: float = 0.8
    align_acceleration: float = 2.0
    grid: float = 0.02
    max_iterations: int = 300
    noise: NoiseLevels = field(default_factory=NoiseLevels)
    torque_offsets: bool = True

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise TrajectoryError(f"objective {self.objective!r}: expected one of {list(OBJECTIVES)}")
        if not (isinstance(self.starts, int) and self.starts >= 1):
            raise TrajectoryError(f"starts={self.starts!r}: expected an integer >= 1")
        lo, hi = self.harmonics
        if not (isinstance(lo, int) and isinstance(hi, int) and 2 <= lo <= hi):
            raise TrajectoryError(f"harmonics={self.harmonics!r}: expected two integers 2 <= fewest <= most")
        for key in ("max_frequency", "min_phase", "steering_excursion", "max_heading", "max_speed", "max_acceleration",
                    "reference_margin", "steering_threshold",
                    "stiction_threshold", "validity", "validity_width", "cond_target", "margin", "align_rate",
                    "align_acceleration", "grid"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise TrajectoryError(f"plan setting {key}={value!r}: expected a finite number > 0")
        for key in ("stiction_guard", "pause", "reference_penalty", "band_penalty", "reversal_window",
                    "reversal_penalty"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise TrajectoryError(f"plan setting {key}={value!r}: expected a finite number >= 0")
        if self.margin > 1:
            raise TrajectoryError(f"margin={self.margin!r}: expected a share of the limits in (0, 1]")
        if self.steering_excursion >= math.pi / 2:
            raise TrajectoryError(f"steering_excursion={self.steering_excursion!r}: expected < pi/2 (the stops)")
        if self.workers is not None and not (isinstance(self.workers, int) and self.workers >= 1):
            raise TrajectoryError(f"workers={self.workers!r}: expected an integer >= 1 or None")

    def threshold(self, coordinate: str) -> float:
        return self.steering_threshold if coordinate.startswith("alpha") else self.stiction_threshold


def parse_floor(text: str) -> FloorSpace:
    """``"5.2x1.6"`` (metres, length along the straight motion x width) as a :class:`FloorSpace`."""
    parts = str(text).lower().replace("*", "x").replace(" ", "").split("x")
    try:
        length, width = (float(p) for p in parts)
    except ValueError:
        raise TrajectoryError(f"floor {text!r}: expected LENGTHxWIDTH in metres, e.g. 5.2x1.6") from None
    if not (math.isfinite(length) and math.isfinite(width) and length > 0 and width > 0):
        raise TrajectoryError(f"floor {text!r}: expected a length and a width > 0 m")
    return FloorSpace(length, width)


# --- the linear structure of a phase ---------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class _PhaseModel:
    """Constant facts of one phase: rows ``z^T P`` (z = (a, v, sign v, 1)), limits, feed-forward."""

    name: str
    mode: Mode
    coordinate: str
    alpha: np.ndarray       # (2,) steering angles at rest of the phase
    P: np.ndarray           # (4, 14): rows of eq. (19) per unit a, v, sign v and the offsets
    sigma: float
    growth: float
    threshold: float
    q_limit: float
    v_limit: float
    a_limit: float
    K: np.ndarray           # (3, 4): motor torque per unit a, v, sign v (eq. 21, nominal parameters)
    torque_limit: float


def _phase_models(geom: Geometry, params: Parameters, floor: FloorSpace, limits: Limits,
                  settings: PlanSettings) -> list[_PhaseModel]:
    half_length = (floor.length - geom.l) / 2
    if half_length <= 0:
        raise TrajectoryError(f"floor {floor.length:g} m x {floor.width:g} m: shorter than the vehicle "
                              f"(l = {geom.l:g} m): the straight motion needs l + 2 max|x_ch| <= the floor length")
    out = []
    for name, mode in PHASES:
        alpha = nominal_steering(geom, mode)
        alpha = np.zeros(2) if alpha is None else np.asarray(alpha, dtype=float)
        coordinate = "alpha_l" if name == "steer_left" else "alpha_r" if name == "steer_right" else mode.coordinates[0]
        col = 1 if name == "steer_right" else 0
        n = mode.dof
        s_dot = np.zeros((3, n))
        s_ddot = np.zeros((3, n))
        s_ddot[0, col] = 1.0
        s_dot[1, col], s_dot[2, col] = 1.0, 2.0
        al = np.tile(alpha, (3, 1))
        qd, qdd = joint_motion(geom, mode, al, s_dot, s_ddot)
        Y = projected_regressor(geom, mode, al, qd, qdd)[:, col, :10]
        u = feedforward_torques(geom, params, mode, al, s_dot, s_ddot)
        H = kinematic_model(geom, mode, al[:1])[0]
        P = np.zeros((4, 10 + _OFFSETS))
        P[0, :10] = Y[0]
        P[1, :10] = Y[2] - Y[1]
        P[2, :10] = 2 * Y[1] - Y[2]
        if settings.torque_offsets:
            P[3, 10:] = geom.i_G * H[5:, col]
        K = np.stack([u[0], u[2] - u[1], 2 * u[1] - u[2]])
        wheel = float(np.max(np.abs(H[5:, col])))
        if mode is Mode.PARKING:
            q_lim, v_lim, a_lim = settings.steering_excursion, limits.steering_rate, limits.steering_acceleration
        elif mode is Mode.ROTATION:
            q_lim, v_lim, a_lim = settings.max_heading, limits.yaw_rate, limits.yaw_acceleration
        else:
            q_lim, v_lim = half_length, min(limits.speed, settings.max_speed)
            a_lim = min(limits.acceleration, settings.max_acceleration)
        if wheel > 0:
            v_lim = min(v_lim, limits.wheel_speed / wheel)
        out.append(_PhaseModel(name, mode, coordinate, alpha, P, settings.noise.of(coordinate),
                               settings.noise.growth(coordinate), settings.threshold(coordinate), q_lim, v_lim, a_lim, K,
                               limits.motor_torque * limits.feedforward_share))
    return out


def _alignments(geom: Geometry, settings: PlanSettings, dt: float) -> list:
    zero = np.zeros(2)
    rot = nominal_steering(geom, Mode.ROTATION)
    kw = dict(pause=settings.pause, rate=settings.align_rate, acceleration=settings.align_acceleration, dt=dt)
    return [alignment(zero, zero, **kw), alignment(zero, zero, **kw), alignment(zero, zero, **kw),
            alignment(zero, rot, **kw), alignment(rot, zero, **kw)]


def _sequence(geom: Geometry, series: dict[str, FourierSeries], settings: PlanSettings, dt: float,
              steering_periods: int = 1, name: str = "plan") -> Trajectory:
    traj = identification_sequence(geom, steer_left=series["steer_left"], steer_right=series["steer_right"],
                                   straight=series["straight"], rotation=series["rotation"],
                                   steering_periods=steering_periods, pause=settings.pause, dt=dt,
                                   align_rate=settings.align_rate, align_acceleration=settings.align_acceleration)
    return replace(traj, name=name)


# --- information of a phase from its Fourier coefficients -------------------------------------------

@dataclass(frozen=True, eq=False)
class _Basis:
    """Fourier basis of one period on a fixed grid ``u = t / T`` in [0, 1): velocity, acceleration
    times T, position over T; and the projector onto series that start and end at rest."""

    H: int
    n: int
    Cv: np.ndarray
    Ca: np.ndarray
    Cq: np.ndarray
    Pi: np.ndarray

    @classmethod
    def of(cls, H: int, n: int) -> "_Basis":
        u = (np.arange(n) + 0.5) / n
        k = np.arange(1, H + 1, dtype=float)
        ph = 2 * np.pi * np.outer(u, k)
        s, c = np.sin(ph), np.cos(ph)
        w = 2 * np.pi * k
        Cv = np.concatenate([c, s], axis=1)
        Ca = np.concatenate([-s * w, c * w], axis=1)
        Cq = np.concatenate([s / w, (1 - c) / w], axis=1)
        # at rest at both ends: sum a_k = 0, sum k b_k = 0 (orthogonal projector)
        N = np.zeros((2 * H, 2))
        N[:H, 0] = 1.0
        N[H:, 1] = k
        Q, _ = np.linalg.qr(N)
        Pi = np.eye(2 * H) - Q @ Q.T
        return cls(H, n, Cv, Ca, Cq, Pi)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1 + np.tanh(0.5 * x))


class _Problem:
    """The objective and its gradient for one start (fixed harmonics per phase)."""

    def __init__(self, models: list[_PhaseModel], harmonics: list[int], available: float, settings: PlanSettings,
                 params: np.ndarray, F0: np.ndarray, U0: np.ndarray, reference_log_std: np.ndarray | None,
                 sample_time: float, grid_points: list[int]):
        self.models = models
        self.bases = [_Basis.of(H, n) for H, n in zip(harmonics, grid_points)]
        self.available = available
        self.settings = settings
        self.log_p = np.log(np.abs(params[:10]))
        self.F0, self.U0 = F0, U0
        self.ref = reference_log_std
        self.Ts = sample_time
        self.t_min = np.array([max(settings.min_phase, 2 * math.pi * H / settings.max_frequency) for H in harmonics])
        if self.t_min.sum() >= available:
            raise TrajectoryError(f"{available:.1f} s for the four phases: too short for phases of at least "
                                  f"{', '.join(f'{x:.1f}' for x in self.t_min)} s; expected a longer --duration")
        self.sizes = [2 * H for H in harmonics]
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])

    # variables: coefficients of the four phases, then four duration logits
    def split(self, x: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        thetas = [x[a:b] for a, b in zip(self.offsets[:-1], self.offsets[1:])]
        return thetas, x[self.offsets[-1]:]

    def durations(self, eta: np.ndarray) -> np.ndarray:
        e = np.exp(eta - eta.max())
        return self.t_min + (self.available - self.t_min.sum()) * e / e.sum()

    def scale(self, j: int, c: np.ndarray, T: float) -> tuple[float, int, int, float]:
        """Largest scale of the series c within the limits of phase j: (scale, limit index, sample, peak)."""
        m, B = self.models[j], self.bases[j]
        v0, a0, q0 = B.Cv @ c, B.Ca @ c / T, T * (B.Cq @ c)
        cands = []
        for k, (x, lim) in enumerate(((v0, m.v_limit), (a0, m.a_limit), (q0, m.q_limit))):
            i = int(np.argmax(np.abs(x)))
            cands.append((lim / max(abs(x[i]), 1e-12), k, i, x[i]))
        y = np.outer(a0, m.K[0]) + np.outer(v0, m.K[1])
        room = m.torque_limit - np.abs(np.outer(np.sign(v0), m.K[2]))
        ratio = np.where(np.abs(y) > 1e-12, np.maximum(room, 1e-9) / np.maximum(np.abs(y), 1e-12), np.inf)
        flat = int(np.argmin(ratio))
        cands.append((float(ratio.flat[flat]), 3, flat, float(y.flat[flat])))
        best = min(cands, key=lambda c_: c_[0])
        return best[0] * self.settings.margin, best[1], best[2], best[3]

    def phase_moments(self, j: int, theta: np.ndarray, T: float, want_grad: bool = False):
        """Moment matrices (4, 4) of phase j in units of T_s rows, noise-weighted (relative to the
        phase's level) for F and unweighted for U, its penalty time (s; see :func:`_row_weights`),
        and what the gradient needs."""
        m, B = self.models[j], self.bases[j]
        c = B.Pi @ theta
        s, kind, i_star, peak = self.scale(j, c, T)
        v0, a0 = B.Cv @ c, B.Ca @ c / T
        v, a = s * v0, s * a0
        wts = _row_weights(v, a, m.threshold, m.growth, m.sigma, self.settings)
        Z = np.stack([a, v, np.sign(v), np.ones_like(v)], axis=1)
        unit = T / B.n / self.Ts
        MF = unit * (Z * wts.wF[:, None]).T @ Z
        MU = unit * (Z * wts.wU[:, None]).T @ Z
        penalty = T / B.n * float(np.sum(wts.pen))
        if not want_grad:
            return MF, MU, penalty, None
        return MF, MU, penalty, (c, s, kind, i_star, peak, v0, a0, Z, wts, unit, T / B.n)

    def information(self, x: np.ndarray, want_grad: bool = False):
        thetas, eta = self.split(x)
        T = self.durations(eta)
        F, U = self.F0.copy(), self.U0.copy()
        cache, band = [], 0.0
        for j, m in enumerate(self.models):
            MF, MU, b, aux = self.phase_moments(j, thetas[j], T[j], want_grad)  # b: penalty time
            F += m.P.T @ MF @ m.P / m.sigma**2
            U += m.P[:, :10].T @ MU @ m.P[:, :10]
            band += b
            cache.append(aux)
        return F, U, T, cache, band / self.available

    def objective(self, x: np.ndarray) -> float:
        F, U, _, _, band = self.information(x)
        return self.criterion(F, U)[0] + band

    def criterion(self, F: np.ndarray, U: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Objective J(F, U) and its derivatives dJ/dF (14, 14), dJ/dU (10, 10)."""
        st = self.settings
        dF, dU = np.zeros_like(F), np.zeros_like(U)
        try:
            Cov = np.linalg.inv(F)
        except np.linalg.LinAlgError:
            return 1e6, dF, dU
        if st.objective == "d-optimal":
            sign, logdet = np.linalg.slogdet(F)
            Foo = F[10:, 10:]
            J = -logdet
            dF = -Cov
            if Foo.size:
                J += np.linalg.slogdet(Foo)[1]
                dF[10:, 10:] += np.linalg.inv(Foo)
            return float(J) / 10, dF / 10, dU
        log_cond, dlc = _log_cond(U)
        if st.objective == "cond":
            return log_cond, dF, dlc
        var = np.diag(Cov)[:10]
        if np.any(var <= 0):
            return 1e6, dF, dU
        log_rel = 0.5 * np.log(var) - self.log_p
        J = float(np.mean(log_rel))
        g = np.full(10, 0.1)  # dJ/dlog_rel
        if self.ref is not None and st.reference_penalty > 0:
            excess = log_rel - self.ref - math.log(st.reference_margin)
            sp, dsp = _softplus(excess, 0.05)
            J += st.reference_penalty * float(np.sum(sp ** 2))
            g += st.reference_penalty * 2 * sp * dsp
        sp, dsp = _softplus(np.array([log_cond - math.log(st.cond_target)]), 0.05)
        J += st.reference_penalty * float(sp[0] ** 2)
        dU = st.reference_penalty * 2 * sp[0] * dsp[0] * dlc
        # d log_rel_i = 0.5 dvar_i / var_i ; dvar_i = -(Cov dF Cov)_ii
        h = np.zeros(F.shape[0])
        h[:10] = g * 0.5 / var
        dF = -(Cov * h) @ Cov
        return J, dF, dU

    def __call__(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        F, U, T, cache, band = self.information(x, want_grad=True)
        J, dF, dU = self.criterion(F, U)
        if J >= 1e6:
            return J, np.zeros_like(x)
        lam = 1.0 / self.available
        J += band
        thetas, eta = self.split(x)
        grad = np.zeros_like(x)
        GF, GU = [], []
        for j, (m, aux) in enumerate(zip(self.models, cache)):
            Gf = m.P @ dF @ m.P.T / m.sigma**2
            Gu = m.P[:, :10] @ dU @ m.P[:, :10].T
            GF.append(0.5 * (Gf + Gf.T))
            GU.append(0.5 * (Gu + Gu.T))
            grad[self.offsets[j]:self.offsets[j + 1]] = self._theta_gradient(j, GF[j], GU[j], lam, aux, T[j])
        # durations: finite differences per phase (the basis lives on t / T, so only scalars change)
        dJ_dT = np.zeros(4)
        for j, m in enumerate(self.models):
            h = 1e-4 * T[j]
            MFp, MUp, bp, _ = self.phase_moments(j, thetas[j], T[j] + h)
            MFm, MUm, bm, _ = self.phase_moments(j, thetas[j], T[j] - h)
            dJ_dT[j] = float(np.sum(GF[j] * (MFp - MFm)) + np.sum(GU[j] * (MUp - MUm)) + lam * (bp - bm)) / (2 * h)
        e = np.exp(eta - eta.max())
        sm = e / e.sum()
        R = self.available - self.t_min.sum()
        dT_deta = R * (np.diag(sm) - np.outer(sm, sm))
        grad[self.offsets[-1]:] = dT_deta.T @ dJ_dT
        return J, grad

    def _theta_gradient(self, j: int, GF: np.ndarray, GU: np.ndarray, lam: float, aux, T: float) -> np.ndarray:
        m, B = self.models[j], self.bases[j]
        c, s, kind, i_star, peak, v0, a0, Z, w, unit, dt_row = aux
        ZF, ZU = Z @ GF, Z @ GU  # (n, 4)
        qF, qU = np.einsum("ni,ni->n", ZF, Z), np.einsum("ni,ni->n", ZU, Z)
        g_a = unit * (2 * w.wF * ZF[:, 0] + 2 * w.wU * ZU[:, 0] + w.wF_a * qF + w.wU_a * qU) + lam * dt_row * w.pen_a
        g_v = unit * (2 * w.wF * ZF[:, 1] + 2 * w.wU * ZU[:, 1] + w.wF_v * qF + w.wU_v * qU) + lam * dt_row * w.pen_v
        # v = s Cv c, a = s Ca c / T
        dc = s * (B.Cv.T @ g_v + B.Ca.T @ g_a / T)
        dJ_ds = float(g_v @ v0 + g_a @ a0)
        # s = margin * limit / |peak(c)|: ds/dc = -s / peak * dpeak/dc
        if kind == 0:
            row = B.Cv[i_star]
        elif kind == 1:
            row = B.Ca[i_star] / T
        elif kind == 2:
            row = T * B.Cq[i_star]
        else:
            i, k = divmod(i_star, 4)
            row = m.K[0, k] * B.Ca[i] / T + m.K[1, k] * B.Cv[i]
        dc += dJ_ds * (-s / peak) * row
        return B.Pi @ dc


@dataclass(frozen=True, eq=False)
class _Weights:
    """Per-row weights of a phase and their partial derivatives in v and a."""

    wF: np.ndarray
    wU: np.ndarray
    pen: np.ndarray
    wF_v: np.ndarray
    wF_a: np.ndarray
    wU_v: np.ndarray
    wU_a: np.ndarray
    pen_v: np.ndarray
    pen_a: np.ndarray


def _row_weights(v: np.ndarray, a: np.ndarray, th: float, growth: float, sigma: float, st: PlanSettings
                 ) -> _Weights:
    """Weights of the rows of a phase in the information (``wF``: noise-weighted, ``wU``: for cond)
    and the penalty per second (``pen``), smooth in the velocity v and acceleration a.

    * validity ``wv``: a smooth step at ``validity`` times the stiction threshold ``th``;
    * contamination ``k``: a row the identification keeps (more than the guard ``g`` after the
      velocity passed ``th``) but within ``reversal_window`` of a velocity reversal: there the
      stick of the reversal, spread by the zero-phase filter, is in the torques. With the
      acceleration a near the reversal, such rows have ``th + g |a| <= |v| < window |a|``
      (empty for slow reversals, ``|a| < th / (window - g)``). They earn no credit and cost
      ``reversal_penalty`` per share of the time;
    * the time below the validity speed costs ``band_penalty`` per share;
    * tyre slip ``r = 1 / (1 + (growth a^2 / sigma)^2)`` (:meth:`NoiseLevels.growth`).
    """
    V, A = np.abs(v), np.abs(a)
    sv, sa = np.sign(v), np.sign(a)
    v_ok = st.validity * th
    width = st.validity_width * v_ok
    wv = _sigmoid((V - v_ok) / width)
    dwv = wv * (1 - wv) / width
    g = st.stiction_guard
    d = 0.2 * th
    k1 = _sigmoid((V - th - g * A) / d)
    k2 = _sigmoid((st.reversal_window * A - V) / d)
    k = k1 * k2
    dk1 = k1 * (1 - k1) / d
    dk2 = k2 * (1 - k2) / d
    k_V = dk1 * k2 - k1 * dk2
    k_A = -g * dk1 * k2 + st.reversal_window * k1 * dk2
    if growth > 0:
        g2 = (growth / sigma) ** 2
        r = 1 / (1 + g2 * a**4)
        r_a = -r**2 * 4 * g2 * a**3
    else:
        r, r_a = np.ones_like(a), np.zeros_like(a)
    wU = wv * (1 - k)
    wU_V = dwv * (1 - k) - wv * k_V
    wU_A = -wv * k_A
    wF = wU * r
    pen = st.band_penalty * (1 - wv) + st.reversal_penalty * k
    return _Weights(wF=wF, wU=wU, pen=pen, wF_v=sv * wU_V * r, wF_a=sa * wU_A * r + wU * r_a,
                    wU_v=sv * wU_V, wU_a=sa * wU_A, pen_v=sv * (-st.band_penalty * dwv + st.reversal_penalty * k_V),
                    pen_a=sa * st.reversal_penalty * k_A)


def _softplus(x: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Smooth max(x, 0) of the given width and its derivative."""
    y = x / width
    sp = width * np.logaddexp(0.0, y)
    return sp, _sigmoid(y)


def _log_cond(U: np.ndarray) -> tuple[float, np.ndarray]:
    """log cond of the column-scaled matrix D U D (D = diag(U)^-1/2) and its derivative in U."""
    d = 1 / np.sqrt(np.diag(U))
    S = U * np.outer(d, d)
    lam, V = np.linalg.eigh(S)
    out = np.zeros_like(U)
    for idx, sign in ((-1, 1.0), (0, -1.0)):
        v = V[:, idx]
        dv = d * v
        grad = np.outer(dv, dv) - lam[idx] * np.diag(v**2 * d**2)
        out += sign * grad / lam[idx]
    return float(np.log(lam[-1] / lam[0])), out


# --- exact evaluation of a sequence ----------------------------------------------------------------

@dataclass(frozen=True)
class SequenceEvaluation:
    """Predicted quality of an identification sequence (exact rows at T_s, the identification's mask).

    ``cond``: cond(Theta_1w^T Theta_1w) of the column-scaled regressor of the ten parameters (eq. 25);
    ``std``: predicted standard deviations (from the information matrix with the noise levels,
    motor-torque offsets estimated alongside); ``floor``: the rectangle it occupies (sec. 6.2);
    ``duration`` s; ``peak_torque`` the largest feed-forward motor torque (N m).
    """

    cond: float
    std: dict[str, float]
    relative_std: dict[str, float]
    floor: FloorSpace
    duration: float
    peak_torque: float
    correlation: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"cond": self.cond, "std": dict(self.std), "relative_std": dict(self.relative_std),
                "floor": {"length": self.floor.length, "width": self.floor.width}, "duration": self.duration,
                "peak_torque": self.peak_torque, "correlation": dict(self.correlation)}


def _coordinates(seg) -> list[tuple[int, str]]:
    if seg.name == "steer_left":
        return [(0, "alpha_l")]
    if seg.name == "steer_right":
        return [(1, "alpha_r")]
    return list(enumerate(seg.mode.coordinates))


def _guarded(keep: np.ndarray, guard: int) -> np.ndarray:
    """``keep`` with rows within ``guard`` samples of a dropped row or an end dropped too."""
    if guard <= 0:
        return keep
    bad = np.concatenate([np.ones(guard, int), (~keep).astype(int), np.ones(guard, int)])
    cs = np.concatenate([[0], np.cumsum(bad)])
    n = keep.size
    return (cs[2 * guard + 1: 2 * guard + 1 + n] - cs[:n]) == 0


def _sequence_rows(traj: Trajectory, settings: PlanSettings, *, validity: bool = False, with_bw: bool = False
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Rows (m, 10 + 4) of eq. (19) the identification keeps (ten parameters, with ``with_bw`` eleven,
    then the offset columns) and the noise level of each row; ``validity``: the optimiser's smooth
    weights instead of the mask."""
    g = traj.geometry
    n_p = 11 if with_bw else 10
    guard = int(round(settings.stiction_guard / traj.sample_time))
    rows, sig = [], []
    for seg in traj.segments:
        if seg.lifted:  # no rows of the vehicle
            continue
        qd, qdd = joint_motion(g, seg.mode, seg.alpha, seg.s_dot, seg.s_ddot)
        Y = projected_regressor(g, seg.mode, seg.alpha, qd, qdd)
        H = kinematic_model(g, seg.mode, seg.alpha)
        for j, coord in ([(0, "alpha_l"), (1, "alpha_r")] if seg.mode is Mode.PARKING else _coordinates(seg)):
            v = seg.s_dot[:, j]
            th = settings.threshold(coord)
            if validity:
                sigma, growth = settings.noise.of(coord), settings.noise.growth(coord)
                keep_w = _row_weights(v, seg.s_ddot[:, j], th, growth, sigma, settings).wF
                keep = keep_w > 1e-6
            else:
                keep = _guarded(np.abs(v) >= th, guard)
                keep_w = keep.astype(float)
            if not keep.any():
                continue
            offs = g.i_G * H[keep, 5:, j] if settings.torque_offsets else np.zeros((int(keep.sum()), _OFFSETS))
            block = np.concatenate([Y[keep, j, :n_p], offs], axis=1) * np.sqrt(keep_w[keep])[:, None]
            rows.append(block)
            sig.append(np.full(int(keep.sum()), settings.noise.of(coord)))
    if not rows:
        return np.zeros((0, n_p + _OFFSETS)), np.zeros(0)
    return np.concatenate(rows), np.concatenate(sig)


def _information(A: np.ndarray, sig: np.ndarray, n_p: int = 10) -> tuple[np.ndarray, np.ndarray]:
    Aw = A / sig[:, None]
    return Aw.T @ Aw, A[:, :n_p].T @ A[:, :n_p]


def evaluate_sequence(traj: Trajectory, params: Parameters = PAPER_PARAMETERS, limits: Limits = Limits(),
                      settings: PlanSettings = PlanSettings(), *, estimate_bw: bool = False) -> SequenceEvaluation:
    """Predicted cond, standard deviations, floor, duration and peak torque of an identification
    sequence, from its planned motion with the identification's stiction mask and guard.

    ``estimate_bw``: B_w estimated with the others (``identify --fix none``) instead of known; its
    std is then in ``std`` too (infinite when the motion does not determine it).
    """
    names = FREE + (("B_w",) if estimate_bw else ())
    n_p = len(names)
    A, sig = _sequence_rows(traj, settings, with_bw=estimate_bw)
    F, U = _information(A, sig, n_p)
    free = [i for i in range(F.shape[0]) if F[i, i] > 0]
    std = np.full(n_p, np.inf)
    corr: dict[str, float] = {}
    try:
        cov = np.linalg.inv(F[np.ix_(free, free)])
        d = np.sqrt(np.maximum(np.diag(cov), 0))
        for k, i in enumerate(free):
            if i < n_p:
                std[i] = d[k]
        r = cov / np.outer(d, d)
        for p_, q_ in (("d_vl", "d_cl"), ("d_vr", "d_cr"), ("d_vw", "d_cw"), ("C_r", "C_ch"), ("C_l", "C_ch")):
            i, j = free.index(FREE.index(p_)), free.index(FREE.index(q_))
            corr[f"{p_}/{q_}"] = float(r[i, j])
    except (np.linalg.LinAlgError, ValueError):
        pass
    cond = _cond(U)
    p = params.to_vector()[:n_p]
    report = limit_report(traj, params, limits)
    return SequenceEvaluation(
        cond=cond, std={n: float(s) for n, s in zip(names, std)},
        relative_std={n: float(s / abs(v)) for n, s, v in zip(names, std, p)},
        floor=floor_space(traj), duration=traj.duration, peak_torque=report.peaks["motor_torque"],
        correlation=corr)


def _cond(U: np.ndarray) -> float:
    diag = np.diag(U)
    if np.any(diag <= 0):
        return math.inf
    d = 1 / np.sqrt(diag)
    lam = np.linalg.eigvalsh(U * np.outer(d, d))
    return float(lam[-1] / lam[0]) if lam[0] > 0 else math.inf


# --- the default sequence in a given floor and duration --------------------------------------------

def default_for_floor(geom: Geometry = PROTOTYPE, floor: FloorSpace | None = None, duration: float | None = None,
                      limits: Limits = Limits(), *, settings: PlanSettings = PlanSettings(),
                      dt: float = SAMPLE_TIME) -> Trajectory:
    """The default identification sequence (``default_excitation``) fitted into a floor and a duration.

    The straight's excursion is scaled down to the floor length; with another total duration the
    periods of the four phases are stretched alike (peak rates kept, excursions scaled down where
    a limit requires it). Without floor and duration: the default sequence itself.
    """
    base = identification_sequence(geom, pause=settings.pause, dt=dt, align_rate=settings.align_rate,
                                   align_acceleration=settings.align_acceleration)
    if floor is None and duration is None:
        return replace(base, name="default")
    aligns = sum(s.duration + dt for s in base.segments if s.name == "align")
    phases = base.duration - aligns
    factor = 1.0 if duration is None else (duration - aligns) / phases
    if factor <= 0.05:
        raise TrajectoryError(f"duration {duration} s: shorter than the alignments of the sequence ({aligns:.1f} s)")
    half = math.inf if floor is None else (floor.length - geom.l) / 2
    if half <= 0:
        raise TrajectoryError(f"floor length {floor.length:g} m: shorter than the vehicle (l = {geom.l:g} m)")
    peaks = {"steer_left": (1.5, 0.9), "steer_right": (1.5, 0.9), "straight": (0.8, 2.0), "rotation": (0.7, 1.6)}
    series = {}
    for name, (v_peak, q_peak) in peaks.items():
        s = default_excitation(name)
        if name == "straight":
            q_peak = min(q_peak, half)
        series[name] = FourierSeries.at_rest(s.base_frequency / factor, s.a, s.b, peak_velocity=v_peak,
                                             peak_excursion=q_peak)
    traj = _sequence(geom, series, settings, dt, steering_periods=default_periods("steer_left"), name="default")
    report = limit_report(traj, PAPER_PARAMETERS, limits)
    if not report.ok:  # a shorter period can break an acceleration limit: scale every phase down to fit
        worst = min(report.limits[k] / report.peaks[k] for k in report.peaks)
        series = {k: FourierSeries(v.base_frequency, tuple(np.array(v.a) * worst * 0.99),
                                   tuple(np.array(v.b) * worst * 0.99)) for k, v in series.items()}
        traj = _sequence(geom, series, settings, dt, steering_periods=default_periods("steer_left"), name="default")
    return traj


# --- the plan --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PhaseDesign:
    """One planned phase: its Fourier series (one period, at rest at both ends) and peaks."""

    name: str
    mode: str
    coordinate: str
    duration: float
    harmonics: int
    series: FourierSeries
    peak_position: float
    peak_velocity: float
    peak_acceleration: float
    limiting: str

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "mode": self.mode, "coordinate": self.coordinate, "duration": self.duration,
                "harmonics": self.harmonics, "peak_position": self.peak_position,
                "peak_velocity": self.peak_velocity, "peak_acceleration": self.peak_acceleration,
                "limiting": self.limiting, "fourier": self.series.to_dict()}


@dataclass(frozen=True, eq=False)
class Plan:
    """Result of :func:`plan`: the planned sequence and its predicted quality next to the default
    sequence in the same floor and duration (``reference``)."""

    trajectory: Trajectory
    phases: tuple[PhaseDesign, ...]
    floor: FloorSpace
    evaluation: SequenceEvaluation
    reference: SequenceEvaluation
    reference_trajectory: Trajectory
    objective: str
    objective_value: float
    starts: tuple[dict[str, Any], ...]
    elapsed: float
    params: Parameters
    settings: PlanSettings
    limits: Limits

    @property
    def cond(self) -> float:
        return self.evaluation.cond

    def to_dict(self) -> dict[str, Any]:
        """Summary (``agvdyn plan --json``)."""
        ev = self.evaluation.to_dict()
        return {
            "objective": self.objective,
            "objective_value": self.objective_value,
            "cond": ev["cond"],
            "floor": {"length": self.floor.length, "width": self.floor.width},
            "floor_used": ev["floor"],
            "duration": ev["duration"],
            "peak_torque": ev["peak_torque"],
            "std": ev["std"],
            "relative_std": ev["relative_std"],
            "correlation": ev["correlation"],
            "phases": [p.to_dict() for p in self.phases],
            "default": {**self.reference.to_dict(), "floor_used": self.reference.to_dict()["floor"]},
            "starts": list(self.starts),
            "elapsed_s": self.elapsed,
            "platform": self.trajectory.geometry.to_dict(),
        }

    def to_yaml_dict(self) -> dict[str, Any]:
        """The trajectory file (YAML segments, docs/simulation.md) that ``simulate`` and ``feedforward`` read."""
        g = self.trajectory.geometry
        rot = [float(x) for x in nominal_steering(g, Mode.ROTATION)]
        st = self.settings
        align = {"pause": st.pause, "rate": st.align_rate, "acceleration": st.align_acceleration}
        ph = {p.name: p for p in self.phases}

        def series(p: PhaseDesign) -> dict[str, Any]:
            return {"base_frequency": p.series.base_frequency, "a": list(p.series.a), "b": list(p.series.b)}

        return {
            "plan": {"objective": self.objective, "cond": self.evaluation.cond,
                     "floor": {"length": self.floor.length, "width": self.floor.width},
                     "duration": self.evaluation.duration, "platform": g.to_dict()},
            "segments": [
                {"name": "align", "to": [0.0, 0.0], **align},
                {"name": "steer_left", "mode": "1", "fourier": {"alpha_l": series(ph["steer_left"])}},
                {"name": "align", "to": [0.0, 0.0], **align},
                {"name": "steer_right", "mode": "1", "fourier": {"alpha_r": series(ph["steer_right"])}},
                {"name": "align", "to": [0.0, 0.0], **align},
                {"name": "straight", "mode": "2s", "fourier": series(ph["straight"])},
                {"name": "align", "to": rot, **align},
                {"name": "rotation", "mode": "4", "fourier": series(ph["rotation"])},
                {"name": "align", "to": [0.0, 0.0], **align},
            ],
        }


def _worker(args) -> tuple[float, np.ndarray, list[int], dict[str, Any]]:
    problem_args, x0, k = args
    problem = _Problem(*problem_args)
    t0 = time.perf_counter()
    res = scipy.optimize.minimize(problem, x0, jac=True, method="L-BFGS-B",
                                  options={"maxiter": problem.settings.max_iterations, "maxcor": 20})
    msg = str(res.message)
    F, U, T, _, band = problem.information(res.x)
    info = {"start": k, "objective": float(res.fun), "iterations": int(res.nit),
            "harmonics": [b.H for b in problem.bases], "durations": [float(x) for x in T],
            "cond_smooth": float(np.exp(_log_cond(U)[0])), "penalty_share": float(band), "message": msg,
            "seconds": time.perf_counter() - t0}
    return float(res.fun), res.x, [b.H for b in problem.bases], info


def plan(geom: Geometry = PROTOTYPE, floor: FloorSpace | str = FloorSpace(5.2, 1.6), duration: float | None = None,
         *, params: Parameters = PAPER_PARAMETERS, limits: Limits = Limits(),
         settings: PlanSettings = PlanSettings(), dt: float = SAMPLE_TIME) -> Plan:
    """Optimal identification sequence (sec. 6.2) for ``geom`` in ``floor`` within ``duration`` s.

    ``duration`` None: the default sequence's (117.6 s on the prototype). ``params``: the nominal
    parameters for the feed-forward torques of the limit check (eq. 21) and the relative stds.
    Raises TrajectoryError when the floor cannot hold the vehicle's rotation or straight motion,
    or the duration is too short for the alignments and four phases.
    """
    t_start = time.perf_counter()
    floor = parse_floor(floor) if isinstance(floor, str) else floor
    rotation_width = math.hypot(geom.l, geom.b) + 2 * abs(geom.a)
    if floor.width < rotation_width - 1e-9 or floor.length < rotation_width - 1e-9:
        raise TrajectoryError(f"floor {floor.length:g} m x {floor.width:g} m: the pure rotation needs a "
                              f"{rotation_width:.3f} m x {rotation_width:.3f} m square (sqrt(l^2 + b^2) + 2a, sec. 6.2)")
    default_traj = default_for_floor(geom, None, None, limits, settings=settings, dt=dt)
    if duration is None:
        duration = default_traj.duration
    reference_traj = default_for_floor(geom, floor, duration, limits, settings=settings, dt=dt)
    reference = evaluate_sequence(reference_traj, params, limits, settings)
    models = _phase_models(geom, params, floor, limits, settings)
    aligns = _alignments(geom, settings, dt)
    align_time = sum(a.n_samples for a in aligns) * dt
    available = duration - align_time
    # constant information of the alignments (the identification uses their rows)
    A0, s0 = _sequence_rows(Trajectory(tuple(aligns[:4]), geom, dt), settings, validity=True)
    A1, s1 = _sequence_rows(Trajectory((aligns[4],), geom, dt), settings, validity=True)
    F0, U0 = _information(np.concatenate([A0, A1]), np.concatenate([s0, s1]))
    F0 = F0 + 1e-12 * np.eye(F0.shape[0])
    ref_rows, ref_sig = _sequence_rows(reference_traj, settings, validity=True)
    Fr, _ = _information(ref_rows, ref_sig)
    try:
        ref_log = 0.5 * np.log(np.diag(np.linalg.inv(Fr))[:10]) - np.log(np.abs(params.to_vector()[:10]))
    except np.linalg.LinAlgError:
        ref_log = None
    rng = np.random.default_rng(settings.seed)
    lo, hi = settings.harmonics
    jobs = []
    base_share = np.array([24.0, 24.0, 30.0, 30.0])
    for k in range(settings.starts):
        share = base_share * np.exp(rng.normal(0, 0.3, 4))
        T0 = share / share.sum() * available
        harmonics = []
        for T in T0:
            cap = max(lo, int(settings.max_frequency * T / (2 * math.pi)))
            harmonics.append(int(rng.integers(lo, min(hi, cap) + 1)))
        t_min = np.array([max(settings.min_phase, 2 * math.pi * H / settings.max_frequency) for H in harmonics])
        if t_min.sum() >= available:
            harmonics = [lo] * 4
            t_min = np.array([max(settings.min_phase, 2 * math.pi * lo / settings.max_frequency)] * 4)
        grid_points = [max(200, int(math.ceil(2 * T / settings.grid))) for T in T0]
        frac = np.clip((T0 - t_min) / max(available - t_min.sum(), 1e-9), 1e-3, None)
        eta0 = np.log(frac / frac.sum())
        if k % 2 == 0:  # the default excitation's shape on this phase's harmonics, perturbed
            thetas = [_default_shape(m.name, H, T, n_) * (1 + 0.2 * k / max(settings.starts, 1))
                      + 0.05 * k / max(settings.starts, 1) * rng.standard_normal(2 * H) / np.tile(np.arange(1, H + 1), 2)
                      for m, H, T, n_ in zip(models, harmonics, T0, grid_points)]
        else:
            thetas = [rng.standard_normal(2 * H) / np.tile(np.arange(1, H + 1), 2) for H in harmonics]
        x0 = np.concatenate([*thetas, eta0])
        problem_args = (models, harmonics, available, settings, params.to_vector(), F0, U0, ref_log, dt, grid_points)
        jobs.append((problem_args, x0, k))
    workers = settings.workers or min(2, os.cpu_count() or 1)
    if workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(max_workers=min(workers, len(jobs))) as pool:
            results = list(pool.map(_worker, jobs))
    else:
        results = [_worker(job) for job in jobs]
    best = min(range(len(results)), key=lambda i: results[i][0])
    fun, x, harmonics, _ = results[best]
    problem = _Problem(*jobs[best][0])
    traj, phases = _build(problem, x, geom, params, limits, settings, dt)
    evaluation = evaluate_sequence(traj, params, limits, settings)
    return Plan(traj, phases, floor, evaluation, reference, reference_traj, settings.objective, float(fun),
                tuple(r[3] for r in results), time.perf_counter() - t_start, params, settings, limits)


_LIMITING = ("velocity", "acceleration", "excursion", "motor torque")


def _default_shape(name: str, H: int, T: float, n: int) -> np.ndarray:
    """Coefficients (2H,) on the basis of a phase of duration T whose velocity is closest (least
    squares) to the default excitation of that phase repeated over T (a start of the optimiser)."""
    series = default_excitation(name)
    B = _Basis.of(H, n)
    t = (np.arange(n) + 0.5) / n * T
    _, v, _ = series.evaluate(t % series.period)
    coef, *_ = np.linalg.lstsq(B.Cv, v / max(np.max(np.abs(v)), 1e-12), rcond=None)
    return B.Pi @ coef


def _build(problem: _Problem, x: np.ndarray, geom: Geometry, params: Parameters, limits: Limits,
           settings: PlanSettings, dt: float) -> tuple[Trajectory, tuple[PhaseDesign, ...]]:
    """The planned trajectory at T_s; a phase whose peaks between grid points break a limit is scaled down."""
    thetas, eta = problem.split(x)
    T = problem.durations(eta)
    series, designs, scales = {}, [], {}
    for j, m in enumerate(problem.models):
        B = problem.bases[j]
        n = max(1, int(round(T[j] / dt)))
        c = B.Pi @ thetas[j]
        s, kind, _, _ = problem.scale(j, c, T[j])
        scales[m.name] = (c, s, kind, n * dt, B.H)
    for _ in range(5):
        series = {}
        for name, (c, s, kind, Tp, H) in scales.items():
            w = 2 * math.pi / Tp
            # velocity amplitudes of the basis on u = t / T are the same on t
            series[name] = FourierSeries(w, tuple(s * c[:H]), tuple(s * c[H:]))
        traj = _sequence(geom, series, settings, dt)
        shrink = _violations(traj, params, limits, problem)
        if not shrink:
            break
        for name, f in shrink.items():
            c, s, kind, Tp, H = scales[name]
            scales[name] = (c, s * f, kind, Tp, H)
    check_limits(traj, params, limits)
    for name, (c, s, kind, Tp, H) in scales.items():
        seg = next(sg for sg in traj.segments if sg.name == name)
        col = 1 if name == "steer_right" else 0
        m = next(mm for mm in problem.models if mm.name == name)
        designs.append(PhaseDesign(
            name=name, mode=m.mode.label, coordinate=m.coordinate, duration=seg.duration + dt, harmonics=H,
            series=series[name], peak_position=float(np.max(np.abs(seg.s[:, col]))),
            peak_velocity=float(np.max(np.abs(seg.s_dot[:, col]))),
            peak_acceleration=float(np.max(np.abs(seg.s_ddot[:, col]))), limiting=_LIMITING[kind]))
    return traj, tuple(designs)


def _violations(traj: Trajectory, params: Parameters, limits: Limits, problem: _Problem) -> dict[str, float]:
    """Per phase, the factor that brings its peaks within the plan's limits (empty: all within)."""
    out = {}
    qd, qdd = traj.joint_motion()
    u = traj.feedforward(params)
    for (name, sl), seg in zip(traj.segment_slices(), traj.segments):
        m = next((mm for mm in problem.models if mm.name == name), None)
        if m is None:
            continue
        col = 1 if name == "steer_right" else 0
        ratios = [m.v_limit / max(np.max(np.abs(seg.s_dot[:, col])), 1e-12),
                  m.a_limit / max(np.max(np.abs(seg.s_ddot[:, col])), 1e-12),
                  m.q_limit / max(np.max(np.abs(seg.s[:, col])), 1e-12)]
        y = np.abs(u[sl]).max()
        if y > m.torque_limit:
            ratios.append(m.torque_limit / y)
        f = min(ratios)
        if f < 1.0:
            out[name] = 0.995 * f
    return out


# --- figure ----------------------------------------------------------------------------------------

def plan_figure(plan_: Plan) -> "Figure":
    """The plan's floor rectangle with the path and footprint of the vehicle, and its phases over time
    (steering angles, chassis travel and heading) next to the default sequence's floor."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    traj = plan_.trajectory
    g = traj.geometry
    fig = Figure(figsize=(11, 6.5), layout="constrained")
    gs = fig.add_gridspec(2, 2, width_ratios=(1.1, 1))
    ax = fig.add_subplot(gs[:, 0])
    pose = traj.pose()
    fl = plan_.floor
    ax.add_patch(Rectangle((-fl.length / 2, -fl.width / 2), fl.length, fl.width, fill=False, lw=2,
                           ec="black", label=f"floor {fl.length:g} m x {fl.width:g} m"))
    used = plan_.evaluation.floor
    ax.add_patch(Rectangle((-used.length / 2, -used.width / 2), used.length, used.width, fill=False, ls="--",
                           ec="tab:blue", label=f"plan uses {used.length:.2f} m x {used.width:.2f} m"))
    ref = plan_.reference.floor
    ax.add_patch(Rectangle((-ref.length / 2, -ref.width / 2), ref.length, ref.width, fill=False, ls=":",
                           ec="tab:gray", label=f"default uses {ref.length:.2f} m x {ref.width:.2f} m"))
    radius = math.hypot(g.l, g.b) / 2 + abs(g.a)
    ax.add_patch(Circle((0, 0), radius, fill=False, ec="tab:orange", ls="-.", label="rotation"))
    xs = pose[:, 0]
    for x_end in (xs.min(), xs.max()):
        ax.add_patch(Rectangle((x_end - g.l / 2, -g.b / 2), g.l, g.b, alpha=0.15, color="tab:blue"))
    ax.plot(pose[:, 0], pose[:, 1], color="tab:blue", lw=1.5, label="chassis centre")
    ax.set_aspect("equal")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.set_title(f"Floor: cond {plan_.evaluation.cond:.2f} (default {plan_.reference.cond:.2f})")
    ax.legend(loc="upper left", fontsize=8)
    margin = 0.2
    ax.set_xlim(-fl.length / 2 - margin, fl.length / 2 + margin)
    ax.set_ylim(-max(fl.width, 2 * radius) / 2 - margin, max(fl.width, 2 * radius) / 2 + margin)
    ax2 = fig.add_subplot(gs[0, 1])
    t = traj.t
    ax2.plot(t, traj.alpha[:, 0], label="alpha_l (rad)")
    ax2.plot(t, traj.alpha[:, 1], label="alpha_r (rad)")
    ax2.plot(t, pose[:, 0], label="x_ch (m)")
    ax2.plot(t, pose[:, 2], label="gamma_ch (rad)")
    for name, sl in traj.segment_slices():
        if name != "align":
            ax2.axvspan(t[sl.start], t[sl.stop - 1], alpha=0.07, color="black")
            ax2.text(t[sl.start], 1.01, name, fontsize=7, va="bottom", transform=ax2.get_xaxis_transform())
    ax2.set_xlabel("t (s)")
    ax2.legend(fontsize=7, ncol=2)
    ax2.set_title("Planned phases")
    ax3 = fig.add_subplot(gs[1, 1])
    names = list(FREE)
    x = np.arange(len(names))
    ax3.bar(x - 0.2, [100 * plan_.reference.relative_std[n] for n in names], 0.4, label="default", color="tab:gray")
    ax3.bar(x + 0.2, [100 * plan_.evaluation.relative_std[n] for n in names], 0.4, label="plan", color="tab:blue")
    ax3.set_xticks(x, names, rotation=45, fontsize=8)
    ax3.set_ylabel("predicted std (% of value)")
    ax3.set_yscale("log")
    ax3.legend(fontsize=8)
    return fig
